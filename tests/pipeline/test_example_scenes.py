"""Every example scene in examples/scenes/ is built and rendered from each of its cameras (small sizes)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from piste.formats.bundle import load_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.preview import ScenePreview, camera_at
from piste.world.scene_file import load_scene

SCENES = Path(__file__).resolve().parents[2] / "examples" / "scenes"
FILES = sorted(SCENES.glob("*.toml"))


def test_there_are_examples():
    assert {p.stem for p in FILES} >= {"default", "blender_lit", "valley"}


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_example_builds_and_renders(path, tmp_path, gl):
    work = tmp_path / "scenes"
    shutil.copytree(SCENES, work, ignore=shutil.ignore_patterns("*.piste", ".piste-cache"))
    scene = load_scene(work / path.name)
    if scene.terrain.kind == "default":  # keep the big course fast: unshadowed bake, coarse cells
        scene.lightmap.shadows = False
        scene.visibility.cell = 250.0
    r = build_scene(scene, out=tmp_path / f"{path.stem}.piste")
    b = load_bundle(r.path)
    assert len(b.net) == r.report["patches"] and b.cameras
    assert b.lightmap.atlas.shape[2] == 3 and np.isfinite(b.lightmap.atlas).all()
    assert b.visibility is not None and b.visibility.n_patches == len(b.net)
    if scene.riders:
        assert b.rider_model() is not None and len(b.rider_lods()) == len(scene.lod.ratios)
    if scene.objects:
        assert len(b.objects()) == len(scene.objects)
    p = ScenePreview(b, size=(96, 64), ctx=gl)
    try:
        for name in b.cameras:
            img = p.render(camera_at(b, name, 0, 2), t=0.1)
            assert img.shape == (64, 96, 3) and img.dtype == np.uint8
            assert img.std() > 2.0, f"camera {name!r} rendered a flat image"
            assert p.stats["drawn_patches"] <= p.stats["frustum_patches"]
    finally:
        p.release()


def test_gltf_example_takes_its_lights_and_cameras_from_the_file(tmp_path):
    scene = load_scene(SCENES / "blender_lit.toml")
    from piste.pipeline.build import scene_cameras, scene_lights

    lights = scene_lights(scene)
    names = [x.name for x in lights]
    assert {"Sun", "Floodlight", "Lantern"} <= set(names)
    from piste.pipeline.sources import load_terrain

    cams = scene_cameras(scene, load_terrain(scene.terrain), None)
    assert [c["name"] for c in cams] == ["Overview", "Valley"]
    assert all(c["source"] == "lights_cameras.gltf" for c in cams)


def test_assets_regenerate_byte_identical(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_assets", SCENES / "make_assets.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    for f in ("hill.png", "valley.npz", "lights_cameras.gltf"):
        assert (tmp_path / f).read_bytes() == (SCENES / "assets" / f).read_bytes(), f
