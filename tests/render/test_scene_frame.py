"""The completed scene, one small frame: riders, objects, shadow patches, stats and timings."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def scene():
    from piste.world.scene import Scene

    return Scene.default(0)


def test_scene_update_cpu_side(scene):
    f = scene.update(1.0)
    assert len(f.riders) == 6
    assert sorted(np.concatenate([idx for idx, _, _ in f.skinned]).tolist()) == list(range(6))
    for level, (idx, pos, nrm) in enumerate(f.skinned):
        assert pos.shape == (len(idx), scene.lods[level].mesh.n_vertices, 3)
        if len(idx):
            # skinned in world space: every rider's vertices lie within 2.5 m of its anchor
            d = np.linalg.norm(pos - f.riders.anchor[idx][:, None], axis=2)
            assert d.max() < 2.5
    assert f.shadow[0].shape == (6, scene.lods[-1].mesh.n_vertices, 3)
    assert f.rider_lights.directions.shape == (6, 3, 3)
    assert f.rider_lod[0] == 0  # the followed rider is close to the camera: high LOD
    assert set(f.timings) >= {"animation", "lod_skinning", "lights", "objects", "cpu"}
    stats = scene.character_stats()
    assert [s["lod"] for s in stats] == ["high", "medium", "low"]
    assert stats[0]["palette"] > stats[1]["palette"] > stats[2]["palette"]
    assert all(s["bones"] == 25 for s in stats)


def test_scene_frame_renders(gl, scene):
    from piste.render.scene_renderer import SceneRenderer, summarize_scene

    r = SceneRenderer(scene, size=(160, 112), ctx=gl)
    try:
        ims = [r.render(t) for t in (0.0, 0.5)]
        no_riders = r.render(0.5, camera=ims[1].scene.camera)  # same frame again: deterministic
    finally:
        r.release()
    im = ims[1]
    assert im.image.shape == (112, 160, 4)
    np.testing.assert_array_equal(im.image, no_riders.image)
    s = im.stats
    assert s["riders"] == 6 and s["rider_triangles"] > 3000
    assert s["objects_drawn"] > 10
    assert 0 < s["shadow_patches"] < 100 and len(s["shadow_patches_per_rider"]) == 6
    assert s["shadow_triangles"] > 0
    for k in ("animation", "lod_skinning", "terrain_lod", "tessellate", "shadow_cull", "cpu", "total"):
        assert im.timings[k] >= 0
    summ = summarize_scene(ims)
    assert summ["frames"] == 2 and summ["fps"] > 0
    # the followed rider stands in the middle of the picture: not sky, not plain snow
    mid = im.image[40:100, 60:100, :3].astype(int)
    assert (mid.max(-1) - mid.min(-1) > 60).any()  # saturated jacket / board colours


def test_demo_full_scene_prints_the_scene_tables(gl_context, tmp_path, capsys):
    from piste.cli import main

    png = tmp_path / "scene.png"
    assert main(["demo", "--size", "96", "64", "--frames", "2", "--out", str(png), "--no-progress",
                 "--lighting", "placeholder", "--objects", "points"]) == 0
    out = capsys.readouterr().out
    assert png.exists()
    for text in ("4x4 patches", "Characters: 6 riders", "palette matrices", "batches", "Objects (compressed",
                 "pre-calculated RGB8", "shadow patches per frame", "CPU side", "animation", "tessellation", "fps"):
        assert text in out, text
