"""Every example scene in examples/scenes/ is built and rendered from each of its cameras (small sizes)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from piste.pipeline.bundle_objects import load_bundle
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


def _assert_close_json(a, b, where="$"):
    """Same structure, strings and integers; floats equal within 1e-9 relative (libm differs by an ulp)."""
    assert type(a) is type(b) or {type(a), type(b)} <= {int, float}, f"{where}: {a!r} vs {b!r}"
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _assert_close_json(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_close_json(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12), f"{where}: {a!r} vs {b!r}"
    else:
        assert a == b, f"{where}: {a!r} vs {b!r}"


def test_assets_regenerate_to_the_committed_values(tmp_path):
    """The committed assets are what make_assets.py makes, compared by value, not by printed float text
    (the last digit of a float's repr depends on the machine's libm)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_assets", SCENES / "make_assets.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    committed = SCENES / "assets"
    a = np.asarray(Image.open(tmp_path / "hill.png"), dtype=np.int64)
    b = np.asarray(Image.open(committed / "hill.png"), dtype=np.int64)
    assert a.shape == b.shape and np.abs(a - b).max() <= 1  # one grey level: a rint at .5 may go either way
    with np.load(tmp_path / "valley.npz") as x, np.load(committed / "valley.npz") as y:
        assert sorted(x.files) == sorted(y.files)
        for k in x.files:
            np.testing.assert_allclose(x[k], y[k], rtol=1e-12, atol=1e-12, err_msg=k)
    _assert_close_json(json.loads((tmp_path / "lights_cameras.gltf").read_text()),
                       json.loads((committed / "lights_cameras.gltf").read_text()))
