"""glTF export: piste's own re-import matches what was written (float32), the Khronos validator
reports 0 errors on every file, atomic writes, terrain/light-map conventions, instancing."""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

import numpy as np
import pygltflib
import pytest

sys.path.insert(0, str(Path(__file__).parent))  # for `from gltf_tools import ...`
from gltf_tools import assert_valid  # noqa: E402

from piste.character import default_rider  # noqa: E402
from piste.errors import ConfigError, ValidationError  # noqa: E402
from piste.formats.gltf import load_gltf  # noqa: E402
from piste.scene_data import AmbientLight, Camera, DirectionalLight, PointLight, SpotLight  # noqa: E402
from piste.formats.gltf_export import (  # noqa: E402
    CharacterExport,
    ObjectsExport,
    TerrainExport,
    export_gltf,
    lightmap_to_png_array,
)
from piste.terrain.net import PatchNet  # noqa: E402
from piste.terrain.tessellate import terrain_mesh  # noqa: E402

DATA = Path("/work/shared/data/gltf")
if not DATA.is_dir():
    DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "gltf"
#: piste (x, y, z) -> glTF (x, z, -y): the root node's rotation
TO_GLTF = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])


def _net(n=4):
    g = np.zeros((3 * n + 1, 3 * n + 1, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(3 * n + 1.0), np.arange(3 * n + 1.0))
    g[..., 2] = 0.3 * np.sin(g[..., 0] / 3) + 0.1 * g[..., 1]
    return PatchNet.from_control_grid(g)


def _atlas(net):
    from piste.render.textures import lightmap_atlas_size

    w, h = lightmap_atlas_size(net, 8)
    rng = np.random.default_rng(1)
    return rng.uniform(0.0, 1.4, (h, w, 3)).astype(np.float32)


def _doc(path):
    g = pygltflib.GLTF2().load(str(path))
    return g, json.loads(g.to_json())


def _accessor(path, g, i):
    """An accessor's data read straight from the file (float32/uint)."""
    a = g.accessors[i]
    bv = g.bufferViews[a.bufferView]
    blob = g.binary_blob() if str(path).endswith(".glb") else (Path(path).parent / g.buffers[0].uri).read_bytes()
    dt = {5126: "<f4", 5121: "u1", 5123: "<u2", 5125: "<u4"}[a.componentType]
    nc = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
    item = np.dtype(dt).itemsize * nc
    stride = bv.byteStride or item
    raw = np.frombuffer(blob, np.uint8, count=stride * (a.count - 1) + item, offset=bv.byteOffset + (a.byteOffset or 0))
    rows = np.lib.stride_tricks.as_strided(raw, (a.count, item), (stride, 1))
    return np.ascontiguousarray(rows).view(dt).reshape(a.count, nc)


# ----------------------------------------------------------------------------- characters
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_rider_round_trip_float32(tmp_path, suffix):
    """The default rider: positions, normals, UVs, skin (joints by bone name, weights, inverse binds)
    and every clip's keys come back from load_gltf exactly as float32."""
    rider = default_rider(seed=0)
    sk = rider.skeleton
    # bind pose = rest pose: the exported rest nodes show the undeformed mesh
    assert np.allclose(np.linalg.inv(sk.world_matrices()), sk.inverse_bind, atol=1e-9)
    out = tmp_path / f"rider{suffix}"
    rep = export_gltf(out, characters=[CharacterExport(rider, name="rider")], up="z")
    assert rep.characters == 1 and rep.animations == len(rider.clips)
    assert_valid(out)
    back = load_gltf(out)
    m0, m1 = rider.meshes[0], back.meshes[0]
    assert np.array_equal(m1.positions, m0.positions)
    assert np.array_equal(m1.indices, m0.indices)
    assert np.allclose(m1.normals, m0.normals, atol=2e-7)
    assert np.array_equal(m1.uv, m0.uv)
    # joints: map exported bone indices by name
    bsk = back.skeleton
    name_of = np.array([bsk.names[j] for j in range(bsk.n_bones)])
    w0 = m0.weights / m0.weights.sum(1, keepdims=True)
    assert np.allclose(m1.weights, w0, atol=1e-6)
    live = w0 > 0
    assert np.array_equal(name_of[m1.joints.astype(int)][live], np.array(sk.names)[m0.joints.astype(int)][live])
    for i, n in enumerate(sk.names):
        j = bsk.bone_index(n)
        assert np.allclose(bsk.inverse_bind[j], sk.inverse_bind[i].astype(np.float32), atol=1e-6)
        assert np.allclose(bsk.rest_rotation[j], sk.rest_rotation[i], atol=1e-6)
    for cname, clip in rider.clips.items():
        c2 = back.clips[cname]
        assert set(c2.tracks) == set(clip.tracks)
        for bone, tracks in clip.tracks.items():
            for path, tr in tracks.items():
                t2 = c2.tracks[bone][path]
                assert t2.interpolation == tr.interpolation
                assert np.array_equal(t2.times, tr.times.astype(np.float32))
                v = tr.values.astype(np.float32).astype(np.float64)
                if path == "rotation":
                    v = v / np.linalg.norm(v, axis=1, keepdims=True)
                assert np.allclose(t2.values, v, atol=1e-7)
        # the posed skin matches too (the whole chain: nodes, skin, clip)
        p0 = clip.sample(0.37, sk, loop=True)
        p1 = c2.sample(0.37, bsk, loop=True)
        a = sk.skin_matrices(p0)
        b = bsk.skin_matrices(p1)[[bsk.bone_index(n) for n in sk.names]]
        assert np.allclose(a, b, atol=2e-5)


def test_morph_targets_and_cubicspline_round_trip(tmp_path):
    """RobotExpressive (morph targets, many clips) and AnimatedMorphCube: morph deltas, names,
    default weights and weight tracks come back."""
    for name in ("RobotExpressive/RobotExpressive.glb", "AnimatedMorphCube/AnimatedMorphCube.glb"):
        src = DATA / name
        if not src.exists():
            pytest.skip(f"{src} missing")
        m = load_gltf(src)
        out = tmp_path / (src.stem + ".glb")
        export_gltf(out, characters=[CharacterExport(m, name=src.stem)], up="z")
        assert_valid(out)
        back = load_gltf(out)
        by_name = {x.name: x for x in back.meshes}
        n_morph = 0
        for a in m.meshes:
            b = by_name[a.name]
            assert np.array_equal(b.positions, a.positions)
            assert np.allclose(b.morph_positions, a.morph_positions, atol=1e-7)
            assert b.morph_names == a.morph_names
            assert np.allclose(b.morph_default_weights, a.morph_default_weights)
            n_morph += a.n_morphs
        assert n_morph > 0
        assert set(back.clips) == set(m.clips)
        for cname, clip in m.clips.items():
            for k, tr in clip.weight_tracks.items():
                assert np.allclose(back.clips[cname].weight_tracks[k].values, tr.values, atol=1e-7)


def test_cesiumman_placed_under_y_up_root(tmp_path):
    """A character placed in piste's Z-up world: load_gltf's posed world positions equal
    ``TO_GLTF @ (placement @ skinned)``."""
    src = DATA / "CesiumMan" / "CesiumMan.glb"
    m = load_gltf(src)
    place = np.eye(4)
    place[:3, 3] = (10.0, -4.0, 2.5)
    out = tmp_path / "cm.glb"
    export_gltf(out, characters=[CharacterExport(m, place, name="cm", prefix="cm:")])
    assert_valid(out)
    back = load_gltf(out)
    clip = next(iter(m.clips))
    p0 = m.skeleton.skin_matrices(m.clips[clip].sample(0.5, m.skeleton))
    p1 = back.skeleton.skin_matrices(back.clips["cm:" + clip].sample(0.5, back.skeleton))
    idx = [back.skeleton.bone_index("cm:" + n) for n in m.skeleton.names]
    want = np.eye(4)
    want[:3, :3] = TO_GLTF
    assert np.allclose(p1[idx], want @ place @ p0, atol=1e-4)


# ----------------------------------------------------------------------------- terrain
@pytest.mark.parametrize("level", [4, 6, 8])
def test_terrain_levels_uv_sets_and_lightmap(tmp_path, level):
    net = _net()
    atlas = _atlas(net)
    base = np.full((8, 8, 4), 200, np.uint8)
    out = tmp_path / f"t{level}.glb"
    rep = export_gltf(out, terrain=TerrainExport(terrain_mesh(net, level), atlas, base))
    mesh = terrain_mesh(net, level)
    assert rep.terrain_triangles == mesh.n_triangles == len(net) * 2 * (level - 1) ** 2
    assert_valid(out)
    g, d = _doc(out)
    prim = d["meshes"][0]["primitives"][0]
    assert set(prim["attributes"]) == {"POSITION", "NORMAL", "TEXCOORD_0", "TEXCOORD_1"}
    mat = d["materials"][prim["material"]]
    assert mat["occlusionTexture"]["texCoord"] == 1
    assert mat["pbrMetallicRoughness"]["baseColorTexture"].get("texCoord", 0) == 0
    assert mat["extras"]["piste_lightmap"]["texCoord"] == 1
    assert np.array_equal(_accessor(out, g, prim["attributes"]["TEXCOORD_1"]), mesh.uv_lightmap)
    assert np.array_equal(_accessor(out, g, prim["attributes"]["TEXCOORD_0"]), mesh.uv)
    # the light-map image is the atlas (8-bit, clamped), decoded from the file
    from PIL import Image
    import io

    tex = d["textures"][mat["occlusionTexture"]["index"]]
    bv = g.bufferViews[g.images[tex["source"]].bufferView]
    img = np.asarray(Image.open(io.BytesIO(g.binary_blob()[bv.byteOffset:bv.byteOffset + bv.byteLength])))
    assert np.array_equal(img, lightmap_to_png_array(atlas))
    assert np.array_equal(img, np.round(np.clip(atlas, 0, 1) * 255))
    # positions through load_gltf: the root turns Z up into Y up
    back = load_gltf(out)
    assert np.allclose(back.meshes[0].positions, mesh.positions.astype(np.float64) @ TO_GLTF.T, atol=1e-5)
    assert np.allclose(np.linalg.norm(back.meshes[0].normals, axis=1), 1.0, atol=1e-5)


def test_terrain_per_edge_levels_and_bad_level(tmp_path):
    from piste.terrain import edge_levels

    net = _net(6)
    lv = edge_levels(net, np.array([0.0, 0.0, 3.0]), near=5.0, far=12.0)
    assert len(set(lv.tolist())) > 1
    out = tmp_path / "lod.gltf"
    rep = export_gltf(out, terrain=TerrainExport(terrain_mesh(net, lv)))
    assert (tmp_path / "lod.bin").exists()
    assert_valid(out)
    assert rep.terrain_triangles == terrain_mesh(net, lv).n_triangles
    with pytest.raises(ConfigError, match="between 2 and 64"):
        terrain_mesh(net, 1)


# ----------------------------------------------------------------------------- objects
def _objects(shear=False):
    from piste.world.objects import make_mesh

    meshes = {}
    for k in ("tree", "rock"):
        om = make_mesh(k)
        meshes[k] = (om.positions, om.normals, om.uv, om.indices)
    from piste.transforms import compose_trs

    rng = np.random.default_rng(3)
    n = 7
    ang = rng.uniform(0, 2 * np.pi, n)
    q = np.stack([np.zeros(n), np.zeros(n), np.sin(ang / 2), np.cos(ang / 2)], 1)
    mats = compose_trs(rng.uniform(-20, 20, (n, 3)), q, rng.uniform(0.5, 2.0, (n, 3)))
    if shear:
        mats[2, 0, 1] += 0.4
    return ObjectsExport(meshes, ("tree", "rock"), np.array([0, 0, 1, 0, 1, 1, 0]), mats,
                         np.full((16, 16, 4), 128, np.uint8))


def test_objects_instancing_ext_and_nodes_agree(tmp_path):
    """Both forms place the same vertices in the world; a sheared instance is baked."""
    o = _objects(shear=True)
    worlds = {}
    for mode in ("ext", "nodes"):
        out = tmp_path / f"o_{mode}.glb"
        rep = export_gltf(out, objects=o, instancing=mode, up="z")
        assert rep.objects == 7 and rep.baked_objects == 1
        assert_valid(out)
        g, d = _doc(out)
        pts = []
        for node in d["nodes"]:
            if "mesh" not in node:
                continue
            pos = _accessor(out, g, d["meshes"][node["mesh"]]["primitives"][0]["attributes"]["POSITION"]).astype(np.float64)
            ext = node.get("extensions", {}).get("EXT_mesh_gpu_instancing")
            if ext:
                from piste.transforms import compose_trs

                a = ext["attributes"]
                mats = compose_trs(_accessor(out, g, a["TRANSLATION"]), _accessor(out, g, a["ROTATION"]),
                                   _accessor(out, g, a["SCALE"]))
            else:
                from piste.transforms import compose_trs

                mats = compose_trs(node.get("translation", [0, 0, 0]), node.get("rotation", [0, 0, 0, 1]),
                                   node.get("scale", [1, 1, 1]))[None]
            for m in mats:
                pts.append(np.sort((pos @ m[:3, :3].T + m[:3, 3]).round(3).view([("", float)] * 3).ravel()))
        worlds[mode] = sorted(p.tobytes() for p in pts)
        if mode == "ext":
            assert "EXT_mesh_gpu_instancing" in d["extensionsUsed"] and "extensionsRequired" not in d
    assert worlds["ext"] == worlds["nodes"] and len(worlds["ext"]) == 7
    # an atlas with cut-out texels (alpha 0) is exported as alphaMode MASK
    o.texture[:4, :4, 3] = 0
    export_gltf(tmp_path / "mask.glb", objects=o)
    assert_valid(tmp_path / "mask.glb")
    _, d = _doc(tmp_path / "mask.glb")
    assert d["materials"][0]["alphaMode"] == "MASK" and d["materials"][0]["alphaCutoff"] == 0.5


# ----------------------------------------------------------------------------- lights, cameras
def test_lights_and_cameras_round_trip(tmp_path):
    """piste's own lights and cameras (scene_data) written as KHR_lights_punctual / glTF cameras
    and read back as the same (axes and units both ways, piste.formats.gltf.units)."""
    lights = [DirectionalLight(direction=(0.3, 0.4, -0.8), color=(1.0, 0.9, 0.8), intensity=1.2, name="sun"),
              PointLight(position=(5.0, 6.0, 7.0), color=(1.0, 0.5, 0.2), intensity=0.7, range=40.0, falloff=2.0,
                         name="lamp"),
              SpotLight(position=(1.0, 2.0, 30.0), direction=(0.0, 0.1, -1.0), color=(0.2, 0.5, 1.0), intensity=0.9,
                        range=60.0, inner_angle=10.0, outer_angle=28.0, falloff=2.0, name="spot"),
              AmbientLight(color=(0.5, 0.5, 0.5), intensity=0.3, name="sky"),  # no glTF form: left out
              PointLight(position=(0.0, 0.0, 5.0), intensity=-0.5, range=10.0, name="dark")]  # likewise
    cams = [Camera(np.array([10.0, -20.0, 15.0]), np.array([10.0, -19.2, 14.4]), fov_y=50.0, aspect=1.5, near=0.5,
                   far=900.0, name="c"),
            Camera(np.array([0.0, 0.0, 100.0]), np.array([0.0, 1.0, 0.0]), near=1.0, far=500.0, aspect=2.0,
                   ortho_height=80.0, name="top")]
    out = tmp_path / "lc.glb"
    report = export_gltf(out, lights=lights, cameras=cams)
    assert_valid(out)
    assert (report.lights, report.cameras) == (3, 2)
    back = load_gltf(out)
    assert [x.name for x in back.lights] == ["sun", "lamp", "spot"]
    for a, b in zip(lights, back.lights):
        assert type(a) is type(b) and np.isclose(a.intensity, b.intensity, rtol=1e-6)
        if not isinstance(a, PointLight):
            assert np.allclose(b.direction, np.asarray(a.direction), atol=1e-6)
        if not isinstance(a, DirectionalLight):
            assert np.allclose(b.position, a.position, atol=1e-5) and np.isclose(b.range, a.range)
    assert np.isclose(back.lights[2].outer_angle, 28.0) and np.isclose(back.lights[2].inner_angle, 10.0)
    c, top = back.cameras
    assert c.name == "c" and np.allclose(c.eye, cams[0].eye, atol=1e-5) and np.isclose(c.fov_y, 50.0)
    assert np.allclose(c.forward, cams[0].forward, atol=1e-6) and (c.near, c.far, c.aspect) == (0.5, 900.0, 1.5)
    assert top.ortho_height == pytest.approx(80.0) and top.aspect == pytest.approx(2.0)
    assert np.allclose(top.forward, cams[1].forward, atol=1e-6)


# ----------------------------------------------------------------------------- bad input, atomic
def test_atomic_failed_export_leaves_old_file(tmp_path):
    net = _net()
    out = tmp_path / "t.glb"
    export_gltf(out, terrain=TerrainExport(terrain_mesh(net)))
    before = out.read_bytes()
    bad = default_rider(seed=0)
    bad.meshes[0].positions[5] = np.nan
    with pytest.raises(ValidationError, match="non-finite"):
        export_gltf(out, terrain=TerrainExport(terrain_mesh(net)), characters=[CharacterExport(bad)])
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.glb"]
    with pytest.raises(ConfigError, match=".glb or .gltf"):
        export_gltf(tmp_path / "t.obj", terrain=TerrainExport(terrain_mesh(net)))
    with pytest.raises(ConfigError, match="no clip"):
        export_gltf(tmp_path / "c.glb", characters=[CharacterExport(default_rider(seed=0), clips=["moonwalk"])])
    assert not (tmp_path / "c.glb").exists()


def test_glb_container_layout(tmp_path):
    out = tmp_path / "t.glb"
    export_gltf(out, terrain=TerrainExport(terrain_mesh(_net()), _atlas(_net())))
    data = out.read_bytes()
    magic, version, length = struct.unpack("<III", data[:12])
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    jlen, jtype = struct.unpack("<II", data[12:20])
    assert jtype == 0x4E4F534A and jlen % 4 == 0
    js = json.loads(data[20:20 + jlen])
    assert js["asset"]["version"] == "2.0" and js["scenes"][0]["nodes"] == [0]
    assert js["nodes"][0]["name"] == "piste" and np.allclose(js["nodes"][0]["rotation"], [-0.5 ** 0.5, 0, 0, 0.5 ** 0.5])


def test_missing_tool_fails_under_require_tools(monkeypatch, tmp_path):
    """With PISTE_REQUIRE_TOOLS=1 a missing validator or Blender fails the test instead of skipping."""
    import gltf_tools

    monkeypatch.setattr(gltf_tools.shutil, "which", lambda name: None)
    monkeypatch.setenv("PISTE_REQUIRE_TOOLS", "1")
    with pytest.raises(pytest.fail.Exception, match="PISTE_REQUIRE_TOOLS=1 but node is not installed"):
        gltf_tools.validate(tmp_path / "x.glb")
    with pytest.raises(pytest.fail.Exception, match="blender is not installed"):
        gltf_tools.blender_import(tmp_path / "x.glb", tmp_path)
    monkeypatch.setenv("PISTE_REQUIRE_TOOLS", "0")
    with pytest.raises(pytest.skip.Exception):
        gltf_tools.validate(tmp_path / "x.glb")
