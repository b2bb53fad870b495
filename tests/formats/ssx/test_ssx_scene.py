"""A scene file with `terrain = { ssx_pbd = "LEVEL.pbd" }`: built, rendered with the level's own
textures and light maps."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import PisteError
from piste.pipeline.ssx_synth import make_level
from piste.pipeline.build import build_scene
from piste.world.scene_file import load_scene


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("ssxscene")
    make_level(rows=2, cols=3, seed=2).write(d, "LV")
    return d


def test_scene_builds_and_renders_the_level(folder, gl):
    from piste.pipeline import load_bundle
    from piste.pipeline.preview import ScenePreview

    scene = folder / "scene.toml"
    scene.write_text('name = "lv"\nterrain = { ssx_pbd = "LV.pbd" }\n\n[render]\nsize = [96, 64]\n')
    s = load_scene(scene)
    assert s.terrain.kind == "ssx_pbd" and s.terrain.path.name == "LV.pbd"
    r = build_scene(scene, use_cache=False)
    b = load_bundle(r.path)
    assert b.arrays["terrain/base_texture"].shape[2] == 4
    assert len(b.net) == 6 and b.lightmap.atlas.max() > 1.0  # the level's own (over-bright) light
    p = ScenePreview(b, ctx=gl)
    try:
        img = p.render().astype(int)
    finally:
        p.release()
    # the rock texture (patches 1 and 4) is dark brown: textured, not plain snow
    brown = (img[..., 0] < 150) & (img[..., 2] < img[..., 0])
    assert brown.mean() > 0.02


def test_source_suffix_and_conflicts(folder):
    scene = folder / "s2.toml"
    scene.write_text('[terrain]\nsource = "LV.pbd"\n')
    assert load_scene(scene).terrain.kind == "ssx_pbd"
    scene.write_text('[terrain]\nsource = "LV.pbd"\nssx_pbd = "LV.pbd"\n')
    with pytest.raises(PisteError, match="ssx_pbd"):
        load_scene(scene)
    scene.write_text('[terrain]\nssx_pbd = "LV.ssh"\n')
    with pytest.raises(PisteError, match=".pbd"):
        load_scene(scene)


def test_ssx_tricky_lod_preset(folder):
    scene = folder / "s3.toml"
    scene.write_text('terrain = { ssx_pbd = "LV.pbd" }\n')
    lod = load_scene(scene).lod
    assert (lod.near, lod.far) == (30.0, 150.0)  # the game's 3000 / 15000 units
    scene.write_text('[lod]\npreset = "ssx_tricky"\nfar = 120.0\n')
    lod = load_scene(scene).lod
    assert (lod.near, lod.far) == (30.0, 120.0)
    scene.write_text('[lod]\npreset = "n64"\n')
    with pytest.raises(PisteError, match="preset"):
        load_scene(scene)


def test_gltf_export_carries_the_level_textures(folder, tmp_path):
    import io

    import pygltflib
    from PIL import Image

    from piste.cli import main
    from piste.pipeline.ssx_level import load_level

    scene = folder / "exp.toml"
    scene.write_text('terrain = { ssx_pbd = "LV.pbd" }\n')
    out = tmp_path / "lv.glb"
    assert main(["export", str(scene), str(out), "--quiet"]) == 0
    g = pygltflib.GLTF2().load(str(out))
    blob = g.binary_blob()
    images = []
    for im in g.images:
        bv = g.bufferViews[im.bufferView]
        images.append(np.asarray(Image.open(io.BytesIO(blob[bv.byteOffset:bv.byteOffset + bv.byteLength]))))
    atlas = load_level(folder / "LV.pbd").base_atlas
    assert any(i.shape == atlas.shape and (i == atlas).all() for i in images)


def test_scene_ps2_mode_blends_the_stored_texels(folder, gl):
    from dataclasses import replace

    from piste.pipeline import load_bundle
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.pipeline.ssx_level import load_level
    from piste.pipeline.ssx_source import level_bundle
    from piste.render.ssx_pass import SsxTerrainRenderer

    scene = folder / "ps2.toml"
    scene.write_text('terrain = { ssx_pbd = "LV.pbd" }\n\n[render]\nsize = [96, 64]\nlightmap_mode = "ps2"\n')
    b = load_bundle(build_scene(scene, use_cache=False).path)
    assert b.arrays["lightmap/source"].dtype == np.uint8
    p = ScenePreview(b, ctx=gl)
    try:
        assert isinstance(p.terrain, SsxTerrainRenderer)
        img = p.render().astype(int)
        cam = replace(camera_at(b), aspect=96 / 64)
    finally:
        p.release()
    level = load_level(folder / "LV.pbd")  # the level opened directly (`piste ssx render`), not built as a scene
    r = ScenePreview(level_bundle(level), size=(96, 64), ctx=gl, lightmap_mode="ps2")
    try:
        want = r.render(cam).astype(int)
    finally:
        r.release()
    assert np.abs(img - want).mean() < 1.0
