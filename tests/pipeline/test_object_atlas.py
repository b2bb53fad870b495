"""glTF objects keep their textures: regions packed into the objects' atlas, UVs remapped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from piste.character.model import Model, SkinnedMesh
from piste.formats.gltf import load_gltf
from piste.pipeline.object_atlas import pack_object_atlas, primitive_images
from piste.world.objects import object_texture

DATA = Path("/work/shared/data/gltf")
if not DATA.is_dir():
    DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "gltf"


def _nearest(img, uv):
    h, w = img.shape[:2]
    x = np.clip(np.round(uv[:, 0] * w - 0.5), 0, w - 1).astype(int)
    y = np.clip(np.round(uv[:, 1] * h - 0.5), 0, h - 1).astype(int)
    return img[y, x]


def test_regions_sample_like_the_original_textures():
    cm = load_gltf(DATA / "CesiumMan" / "CesiumMan.glb")
    solid = SkinnedMesh("red", np.zeros((3, 3)), np.array([[0, 1, 2]]), base_color=np.array([1.0, 0.0, 0.0, 1.0]))
    model = Model("m", None, [cm.meshes[0], solid])
    imgs = primitive_images(model)
    assert imgs[0][2].shape == cm.meshes[0].texture.shape and imgs[1][2][0, 0].tolist() == [255, 0, 0, 255]
    uv = np.concatenate([cm.meshes[0].uv, np.full((3, 2), 0.5, np.float32)])
    base = object_texture()
    atlas, new = pack_object_atlas(base, {"gltf_cm": (uv, imgs)}, max_size=4096)
    assert np.array_equal(atlas[:base.shape[0], :base.shape[1]], base)  # the built-in tiles stay put
    nv = cm.meshes[0].n_vertices
    tex = cm.meshes[0].texture
    h, w = tex.shape[:2]
    # texel-centre mapping: original texel (round(u (w-1)), round(v (h-1))) is the atlas texel sampled
    u = np.clip(cm.meshes[0].uv.astype(np.float64), 0, 1)
    want = tex[np.round(u[:, 1] * (h - 1)).astype(int), np.round(u[:, 0] * (w - 1)).astype(int)]
    got = _nearest(atlas, new["gltf_cm"][:nv].astype(np.float64))
    assert (np.abs(got.astype(int) - want.astype(int)).max(axis=1) <= 0).mean() > 0.99
    assert (_nearest(atlas, new["gltf_cm"][nv:]) == [255, 0, 0, 255]).all()
    # regions never overlap the base and stay inside the atlas
    assert new["gltf_cm"].min() >= 0 and new["gltf_cm"].max() <= 1
    assert (new["gltf_cm"][:, 1] * atlas.shape[0] >= base.shape[0]).all()


def test_scene_with_a_gltf_object_keeps_its_texture(tmp_path):
    """A scene's glTF object (CesiumMan's mesh): the bundle's object atlas holds its texture and
    the object's decoded UVs sample it (what the object pass draws)."""
    import shutil

    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.world.scene_file import load_scene

    shutil.copy(DATA / "CesiumMan" / "CesiumMan.glb", tmp_path / "man.glb")
    n, spacing = 9, 4.0
    y, x = np.mgrid[0:n, 0:n] * spacing
    np.savez(tmp_path / "hill.npz", z=10.0 - 0.1 * y, dx=np.float64(spacing))
    (tmp_path / "s.toml").write_text("""name = "statue"
[terrain]
source = "hill.npz"
[lightmap]
res = 8
[visibility]
enabled = false
[[objects]]
model = "man.glb"
position = [16.0, 16.0]
scale = 3.0
[[objects]]
model = "builtin:tree"
position = [8.0, 8.0]
[[cameras]]
name = "main"
eye = [16.0, 2.0, 14.0]
target = [16.0, 16.0, 11.0]
""")
    b = load_bundle(build_scene(load_scene(tmp_path / "s.toml"), out=tmp_path / "s.piste").path)
    objs = b.objects()
    k = [x for x in objs.kinds if x.startswith("gltf_")][0]
    _, _, uv = objs.meshes[k].decode()
    tex = load_gltf(DATA / "CesiumMan" / "CesiumMan.glb").meshes[0].texture
    src_uv = np.clip(load_gltf(DATA / "CesiumMan" / "CesiumMan.glb").meshes[0].uv.astype(np.float64), 0, 1)
    atlas = objs.texture
    got = _nearest(atlas, uv.astype(np.float64)).astype(int)
    h, w = tex.shape[:2]
    if max(h, w) <= 256:
        want = tex[np.round(src_uv[:, 1] * (h - 1)).astype(int), np.round(src_uv[:, 0] * (w - 1)).astype(int)]
        assert (np.abs(got - want).max(axis=1) <= 2).mean() > 0.95  # 16-bit UV quantization
    else:  # scaled down into the atlas: colours agree on average
        want = tex[np.round(src_uv[:, 1] * (h - 1)).astype(int), np.round(src_uv[:, 0] * (w - 1)).astype(int)]
        assert np.abs(got[:, :3].mean(0) - want[:, :3].mean(0)).max() < 12
    # the built-in tree still samples the built-in tiles (top-left of the atlas)
    _, _, tuv = objs.meshes["tree"].decode()
    assert (tuv[:, 1] * atlas.shape[0] <= object_texture().shape[0]).all()


def test_double_sided_materials_get_back_faces():
    from dataclasses import replace

    from piste.formats.gltf_ext import MaterialInfo
    from piste.world.objects import ObjectMesh

    a = SkinnedMesh("a", np.eye(3), np.array([[0, 1, 2]]), material=MaterialInfo(double_sided=True))
    b = SkinnedMesh("b", np.eye(3) + 2, np.array([[0, 1, 2]]), material=MaterialInfo())
    model = Model("m", None, [a, b])
    merged = ObjectMesh("m", np.concatenate([a.positions, b.positions]), np.concatenate([a.normals, b.normals]),
                        np.zeros((6, 2)), np.array([[0, 1, 2], [3, 4, 5]]))
    from piste.pipeline.object_atlas import double_sided

    out, imgs = double_sided(merged, model, primitive_images(model))
    assert out.n_vertices == 9 and len(out.indices) == 3
    assert out.indices[2].tolist() == [8, 7, 6]  # a's triangle reversed on its copies
    assert np.allclose(out.normals[6:], -a.normals) and np.allclose(out.positions[6:], a.positions)
    assert [(x[0], x[1]) for x in imgs] == [(0, 3), (3, 6), (6, 9)]
    same, imgs2 = double_sided(merged, replace(model, meshes=[b, b]), primitive_images(model))
    assert same is merged and len(imgs2) == 2


@pytest.mark.gl
def test_rendered_gltf_object_shows_its_own_texture(tmp_path, gl):
    """A magenta-textured glTF box placed in a scene is drawn magenta (the built-in atlas has no
    magenta): the object pass samples the object's own region of the atlas."""
    from piste.formats.gltf_export import CharacterExport, export_gltf
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.preview import ScenePreview
    from piste.world.objects import make_mesh
    from piste.world.scene_file import load_scene

    box = make_mesh("sign")
    tex = np.zeros((8, 8, 4), np.uint8)
    tex[...] = (255, 0, 255, 255)
    mesh = SkinnedMesh("box", box.positions @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T * 4,  # piste Z up -> glTF Y up
                       box.indices, normals=box.normals @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T,
                       uv=np.full((box.n_vertices, 2), 0.5), texture=tex)
    export_gltf(tmp_path / "magenta.glb", characters=[CharacterExport(Model("box", None, [mesh]), name="box")], up="z")
    from dataclasses import replace

    from piste.formats.gltf_ext import MaterialInfo

    clear = tex.copy()
    clear[...] = (0, 255, 0, 0)  # green, fully transparent, alpha MASK: never drawn
    hidden = replace(mesh, texture=clear, material=MaterialInfo(alpha_mode="MASK", alpha_cutoff=0.5),
                     positions=mesh.positions + [0.0, 0.0, -3.0])
    export_gltf(tmp_path / "clear.glb", characters=[CharacterExport(Model("clear", None, [hidden]), name="c")], up="z")
    n, spacing = 9, 4.0
    y, x = np.mgrid[0:n, 0:n] * spacing
    np.savez(tmp_path / "hill.npz", z=np.zeros_like(x, dtype=float), dx=np.float64(spacing))
    (tmp_path / "s.toml").write_text("""name = "magenta"
[terrain]
source = "hill.npz"
[lightmap]
res = 8
[visibility]
enabled = false
[[objects]]
model = "magenta.glb"
position = [16.0, 16.0]
[[objects]]
model = "clear.glb"
position = [16.0, 16.0]
heading = 30.0
[[lights]]
type = "ambient"
intensity = 1.0
[[cameras]]
name = "main"
eye = [16.0, -2.0, 8.0]
target = [16.0, 16.0, 2.0]
""")
    b = load_bundle(build_scene(load_scene(tmp_path / "s.toml"), out=tmp_path / "s.piste").path)
    p = ScenePreview(b, size=(96, 64), ctx=gl)
    try:
        img = p.render(b.camera("main"), t=0.0).astype(int)
    finally:
        p.release()
    magenta = (img[..., 0] > img[..., 1] + 60) & (img[..., 2] > img[..., 1] + 60)
    assert magenta.sum() > 50, magenta.sum()
    green = (img[..., 1] > img[..., 0] + 60) & (img[..., 1] > img[..., 2] + 60)
    assert green.sum() == 0, green.sum()


def test_alpha_modes_baked_for_the_shader():
    from piste.formats.gltf_ext import MaterialInfo

    tex = np.zeros((2, 2, 4), np.uint8)
    tex[..., :3] = 200
    tex[..., 3] = [[10, 100], [150, 250]]
    meshes = [SkinnedMesh(mode, np.eye(3), np.array([[0, 1, 2]]), texture=tex,
                          material=MaterialInfo(alpha_mode=mode, alpha_cutoff=0.5 if mode != "MASK" else 0.3))
              for mode in ("OPAQUE", "MASK", "BLEND")]
    imgs = primitive_images(Model("m", None, meshes))
    assert (imgs[0][2][..., 3] == 255).all()
    assert imgs[1][2][..., 3].tolist() == [[0, 255], [255, 255]]  # cutoff 0.3 = 77
    assert imgs[2][2][..., 3].tolist() == [[10, 100], [150, 250]]  # BLEND: the alpha as it is
    from piste.pipeline.object_atlas import blends

    assert blends(Model("m", None, meshes)) and not blends(Model("m", None, meshes[:2]))


def test_rider_with_several_materials_keeps_each_colour():
    """RobotExpressive as a rider: its 19 skinned primitives (base-colour factors, no textures) merge
    into one mesh whose packed texture gives every vertex its own primitive's colour."""
    from piste.pipeline.characters import merged_mesh
    from piste.pipeline.object_atlas import _srgb_u8

    m = load_gltf(DATA / "RobotExpressive" / "RobotExpressive.glb")
    prims = [x for x in m.meshes if x.skinned]
    mm = merged_mesh(m)
    got = _nearest(mm.texture, mm.uv.astype(np.float64))
    want = np.concatenate([np.tile(_srgb_u8(p.base_color), (p.n_vertices, 1)) for p in prims])
    assert np.array_equal(got, want)
    assert len({tuple(c) for c in want.tolist()}) >= 3
    # a single-primitive rider is untouched (the default rider's texture and UVs stay as they are)
    from piste.character import default_rider

    r = default_rider(0)
    assert merged_mesh(r) is r.meshes[0]


@pytest.mark.gl
def test_scene_gltf_blend_object_is_drawn_half_transparent(tmp_path, gl):
    """A scene file's glTF object with alphaMode BLEND (red, alpha 128) in front of an opaque
    magenta one: the bundle marks its kind blended and the preview draws the blend of both."""
    from dataclasses import replace

    from piste.formats.gltf_ext import MaterialInfo
    from piste.formats.gltf_export import CharacterExport, export_gltf
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.preview import ScenePreview
    from piste.world.objects import make_mesh
    from piste.world.scene_file import load_scene

    box = make_mesh("sign")
    rot = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T  # piste Z up -> glTF Y up
    tex = np.zeros((8, 8, 4), np.uint8)
    tex[...] = (255, 0, 255, 255)
    mesh = SkinnedMesh("box", box.positions @ rot * 4, box.indices, normals=box.normals @ rot,
                       uv=np.full((box.n_vertices, 2), 0.5), texture=tex)
    export_gltf(tmp_path / "magenta.glb", characters=[CharacterExport(Model("box", None, [mesh]), name="box")], up="z")
    red = tex.copy()
    red[...] = (255, 0, 0, 128)
    quad = np.array([[-4.0, 0, 0], [0, 0, 0], [0, 0, 12], [-4, 0, 12]])  # one layer, facing the camera (-y)
    glass = SkinnedMesh("glass", quad @ rot, np.array([[0, 1, 2], [0, 2, 3]]), normals=np.tile([0.0, -1, 0], (4, 1)) @ rot,
                        uv=np.full((4, 2), 0.5), texture=red, material=MaterialInfo(alpha_mode="BLEND"))
    export_gltf(tmp_path / "glass.glb", characters=[CharacterExport(Model("glass", None, [glass]), name="g")], up="z")
    n, spacing = 9, 4.0
    np.savez(tmp_path / "hill.npz", z=np.zeros((n, n)), dx=np.float64(spacing))
    (tmp_path / "s.toml").write_text("""name = "glass"
[terrain]
source = "hill.npz"
[lightmap]
res = 8
[visibility]
enabled = false
[[objects]]
model = "glass.glb"
position = [16.0, 10.0]
[[objects]]
model = "magenta.glb"
position = [16.0, 16.0]
[[lights]]
type = "ambient"
intensity = 1.0
[[cameras]]
name = "main"
eye = [16.0, -2.0, 8.0]
target = [16.0, 16.0, 2.0]
""")
    b = load_bundle(build_scene(load_scene(tmp_path / "s.toml"), out=tmp_path / "s.piste").path)
    objs = b.objects()
    assert objs.blend == ("gltf_glass",)
    p = ScenePreview(b, size=(96, 64), ctx=gl)
    try:
        img = p.render(b.camera("main"), t=0.0).astype(int)
    finally:
        p.release()
    r, g, bl = img[..., 0], img[..., 1], img[..., 2]
    magenta = (r > g + 60) & (np.abs(bl - r) < 0.15 * r)
    blended = (g < 30) & (r > 150) & (bl > 0.35 * r) & (bl < 0.65 * r)  # red over magenta: blue halved
    assert magenta.sum() > 20 and blended.sum() > 20, (magenta.sum(), blended.sum())
