"""A scene with two rider models (the built-in rider and a glTF character): the bundle holds one
character per model (its own LODs, palettes, batches, clips) and the preview draws both."""

from __future__ import annotations

import shutil

import numpy as np
import pytest


CESIUM = """\
[[riders]]
name = "cesium"
model = "CesiumMan.glb"
position = [66.0, 58.0]
"""


def test_two_models_built_and_drawn(small_scene, gl, gltf_model, piste_cache):
    import os
    from pathlib import Path

    from piste.pipeline import build_scene, load_bundle
    from piste.pipeline.preview import BundleScene, ScenePreview, camera_at
    from piste.world.scene_file import load_scene

    gltf_model("CesiumMan")  # skips without the test data
    data = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
    scene = small_scene(riders=True)
    shutil.copy(data / "gltf" / "CesiumMan" / "CesiumMan.glb", scene.parent / "CesiumMan.glb")
    text = scene.read_text().replace('[[objects]]\nname = "tree"', CESIUM + '\n[[objects]]\nname = "tree"', 1)
    scene.write_text(text)
    out = scene.with_suffix(".piste")
    build_scene(load_scene(scene), out=out)
    b = load_bundle(out)
    chars = b.manifest["characters"]
    assert sorted(chars) == ["rider", "rider2"]
    assert chars["rider2"]["model"] == "CesiumMan.glb" and chars["rider"]["model"] == "builtin:rider"
    assert [r["character"] for r in b.manifest["riders"]] == ["rider", "rider2"]
    assert chars["rider"]["lods"][0]["triangles"] != chars["rider2"]["lods"][0]["triangles"]
    bs = BundleScene(b)
    assert len(bs.riders) == 1 and len(bs.casts) == 1 and len(bs.casts[0].riders) == 1
    assert bs.casts[0].model.skeleton.n_bones != bs.model.skeleton.n_bones
    p = ScenePreview(b, size=(96, 64), ctx=gl)
    try:
        img = p.render(camera_at(b), 0.3)
        assert p.stats["riders"] == 2 and p.stats["rider_models"] == 2
        assert p.stats["rider_triangles"] == sum(
            c["lods"][lvl]["triangles"] for c, lvl in zip((chars["rider"], chars["rider2"]), p.stats["rider_lod"]))
    finally:
        p.release()
    assert img.shape == (64, 96, 3) and np.asarray(img).std() > 2
