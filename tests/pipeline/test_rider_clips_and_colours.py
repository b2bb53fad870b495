"""Issue 25's symptoms of the three front doors: a ``--rider-model`` glTF of base-colour factors
keeps its colours at run time (as a scene file's rider does), and two riders of one model, one
with ``clips_from``, each default to their own clips."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

DATA = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))


def test_rider_model_flag_keeps_each_primitives_colour(gltf_model):
    from piste.pipeline.characters import merged_mesh
    from piste.pipeline.preview import rider_casts
    from piste.world.riders import rider_model

    src = gltf_model("RobotExpressive")  # 19 skinned primitives: base-colour factors, no textures
    (model, rows), = rider_casts([str(DATA / "gltf" / "RobotExpressive" / "RobotExpressive.glb") + ":2"])
    assert len(rows) == 2
    tex = model.meshes[0].texture
    built = merged_mesh(src)  # what a scene file's rider gets (the characters build step)
    assert np.array_equal(tex, built.texture) and np.array_equal(model.meshes[0].uv, built.uv)
    h, w = tex.shape[:2]
    uv = model.meshes[0].uv.astype(np.float64)
    x = np.clip(np.round(uv[:, 0] * w - 0.5), 0, w - 1).astype(int)
    y = np.clip(np.round(uv[:, 1] * h - 0.5), 0, h - 1).astype(int)
    colours = {tuple(c) for c in tex[y, x, :3].tolist()}
    assert len(colours) >= 3  # each primitive its own colour
    white = rider_model(src).meshes[0].texture  # (the bug: merged without its materials)
    assert {tuple(c) for c in white.reshape(-1, 4)[:, :3].tolist()} == {(255, 255, 255)}


def test_riders_of_one_model_default_to_their_own_clips(small_scene, gltf_model, piste_cache):
    from piste.pipeline import build_scene, load_bundle
    from piste.world.scene_file import load_scene

    gltf_model("Fox")  # skips without the test data
    scene = small_scene(riders=False)
    shutil.copy(DATA / "gltf" / "Fox" / "Fox.glb", scene.parent / "Fox.glb")
    riders = ('[[riders]]\nname = "own"\nposition = [60.0, 60.0]\n\n'
              '[[riders]]\nname = "foxy"\nposition = [66.0, 58.0]\nclips_from = "Fox.glb"\n\n')
    scene.write_text(scene.read_text().replace('[[objects]]\nname = "tree"', riders + '[[objects]]\nname = "tree"', 1))
    out = scene.with_suffix(".piste")
    for _ in range(2):  # built, then from the step cache
        build_scene(load_scene(scene), out=out)
        b = load_bundle(out)
        clips = {r["name"]: r["clip"] for r in b.manifest["riders"]}
        assert {"crouch", "Run", "Survey", "Walk"} <= set(b.manifest["characters"]["rider"]["clips"])  # pooled
        assert clips == {"own": "crouch", "foxy": "Run"}  # was: both "Run" (the pool's first, alphabetically)
        assert "own_clips" not in b.manifest["characters"]["rider"]
