"""Riders' levels of detail chosen by their error in pixels (the objects' rule), not by distance."""

from __future__ import annotations

import numpy as np
import pytest

from piste.scene_data import Camera


@pytest.fixture(scope="module")
def scene():
    from piste.world.scene import Scene

    return Scene.default(0, objects=False)


def _looking_at(state, eye_offset):
    """A camera ``eye_offset`` from rider 0's middle, looking at it."""
    mid = state.anchor[0] + 0.9 * state.normal[0]
    return Camera(eye=mid + np.asarray(eye_offset, float), target=mid)


def test_errors_grow_with_the_level_and_include_the_palette(scene):
    from piste.character.lod import lod_errors

    err = scene.rider_lod_errors()
    geo = lod_errors(scene.lods)
    assert err.shape == (len(scene.lods),) and err[0] == 0.0
    assert (np.diff(err) > 0).all()
    # the coarser palettes move vertices too: the error is more than the bind-pose distance alone
    assert (err[1:] > geo[1:] + 1e-3).all()
    assert scene.rider_lod_errors() is err  # computed once


def test_near_rider_full_mesh_far_rider_coarser(scene):
    st = scene.riders.state(0.0)
    err = scene.rider_lod_errors()
    r = scene.rider_radius()
    f = 1.0 / np.tan(np.radians(30.0)) * 0.5 * 448.0  # pixels per metre at depth 1
    levels = []
    for dist in (r + 2.0, r + f * err[1] * 1.2, r + f * err[-1] * 1.2, 400.0):
        cam = _looking_at(st, [dist, 0.0, 0.0])
        levels.append(int(scene.choose_rider_lods(st, cam, 448)[0]))
    assert levels[0] == 0  # near: the full mesh
    assert levels[1] >= 1 and levels[2] == len(err) - 1 and levels[3] == len(err) - 1
    assert levels == sorted(levels)  # farther never finer
    # the same rider on a taller viewport (more pixels per metre) keeps a finer level
    cam = _looking_at(st, [r + f * err[1] * 1.2, 0.0, 0.0])
    assert int(scene.choose_rider_lods(st, cam, 448 * 4)[0]) < levels[1]


def test_a_larger_pixel_bound_never_draws_more_triangles(scene):
    tris = np.array([lod.n_triangles for lod in scene.lods])
    keep = scene.lod_pixels
    try:
        for t in (0.0, 1.5, 4.0):
            counts = []
            for px in (0.25, 0.5, 1.0, 2.0, 8.0):
                scene.lod_pixels = px
                f = scene.update(t)
                counts.append(int(tris[f.rider_lod].sum()))
                # every rider is skinned at the level chosen for it
                for level, (idx, pos, _) in enumerate(f.skinned):
                    assert (f.rider_lod[idx] == level).all() and pos.shape[1] == scene.lods[level].mesh.n_vertices
            assert all(a >= b for a, b in zip(counts, counts[1:])), counts
            assert counts[0] > counts[-1]
    finally:
        scene.lod_pixels = keep


def test_zero_pixels_is_the_distance_rule_and_default_is_by_pixels(scene):
    from piste.world.scene import RIDER_LOD_PIXELS

    assert scene.lod_pixels == RIDER_LOD_PIXELS == 1.0
    f = scene.update(0.0)
    assert f.rider_lod[0] == 0  # the chased rider: full mesh
    assert f.rider_lod.max() == len(scene.lods) - 1  # the pack's far riders: the coarsest
    keep = scene.lod_pixels
    try:
        scene.lod_pixels = 0.0
        g = scene.update(0.0)
    finally:
        scene.lod_pixels = keep
    d = np.linalg.norm(g.riders.anchor - g.camera.eye, axis=1)
    assert (g.rider_lod == np.searchsorted(np.asarray(scene.lod_distances), d)).all()
    # the default scene: the pixel rule draws fewer rider triangles than the distance rule
    tris = np.array([lod.n_triangles for lod in scene.lods])
    assert tris[f.rider_lod].sum() < tris[g.rider_lod].sum()


def test_choice_is_the_objects_rule_and_casters_stay_the_coarsest(scene):
    from piste.world.object_lod import choose_lods

    keep = scene.lod_pixels
    try:
        for t in (0.0, 2.0):
            f = scene.update(t)
            st, cam = f.riders, f.camera
            for px in (0.3, 1.0, 2.5):
                scene.lod_pixels = px
                n = len(st)
                want = choose_lods(scene.rider_lod_errors(), st.anchor + 0.9 * st.normal, np.full(n, scene.rider_radius()),
                                   np.ones(n), cam.view_projection(), 448.0, px)
                assert (scene.choose_rider_lods(st, cam, 448) == want).all()
            scene.lod_pixels = keep
            # the shadow casters: every rider at the coarsest level (never finer than what is drawn)
            low, _ = scene.skinners[-1].apply_many(st.skin, normalize=False)
            assert np.array_equal(f.shadow[0], low)
    finally:
        scene.lod_pixels = keep


def test_a_bundles_levels_carry_their_error_measured_at_build():
    """The character step stores each level's error (meta ``distance``); a scene on those levels uses it
    as stored (no measuring at its first frame), and it is what measuring them again gives."""
    from dataclasses import replace

    from piste.character import default_rider
    from piste.character.lod import pose_skins, screen_errors
    from piste.pipeline.characters import character_arrays, lods_from_arrays, model_from_arrays
    from piste.world.scene import Scene

    arrays, meta = character_arrays(default_rider(0))
    a = {f"characters/rider/{k}": v for k, v in arrays.items()}
    model = model_from_arrays(a, "characters/rider/", meta)
    lods = lods_from_arrays(a, "characters/rider/", meta, model)
    stored = np.array([lod.distance for lod in lods])
    assert stored[0] == 0.0 and (np.diff(stored) > 0).all()
    np.testing.assert_array_equal(stored, screen_errors(lods, pose_skins(model)))
    # a scene takes the stored values as they are (made-up ones here: it must not measure them again)
    scene = Scene.default(0, objects=False, model=model)
    scene.lods = [replace(lod, distance=d) for lod, d in zip(lods, (0.0, 0.5, 0.75))]
    np.testing.assert_array_equal(scene.rider_lod_errors(), [0.0, 0.5, 0.75])
    # a bundle from before the errors were stored: measured on use
    meta_old = {**meta, "lods": [{k: v for k, v in info.items() if k != "distance"} for info in meta["lods"]]}
    old = lods_from_arrays(a, "characters/rider/", meta_old, model)
    assert all(lod.distance is None for lod in old)


def test_the_built_in_riders_measured_errors_are_current(scene):
    """MEASURED_ERRORS spares a fresh process measuring the built-in rider's levels at its first frame:
    the entry must be what measuring them gives now (update it when the rider or its levels change)."""
    from piste.character.lod import MEASURED_ERRORS, lod_digest, pose_skins, screen_errors

    d = lod_digest(scene.lods, scene.model)
    assert d in MEASURED_ERRORS, f"the built-in rider's levels changed: add MEASURED_ERRORS[{d!r}]"
    assert MEASURED_ERRORS[d] == tuple(float(x) for x in screen_errors(scene.lods, pose_skins(scene.model)))
    # other levels of the same model (another palette step) are not found: measured on use
    from piste.character.lod import make_lods

    assert lod_digest(make_lods(scene.lods[0].mesh, steps=0.1), scene.model) not in MEASURED_ERRORS


def test_scene_file_sets_the_riders_pixel_bound(tmp_path):
    from piste.errors import ConfigError
    from piste.world.scene_file import load_scene

    p = tmp_path / "s.toml"
    p.write_text("")
    assert load_scene(p).lod.character_pixels == 1.0
    p.write_text("[lod]\ncharacter_pixels = 0\n")
    assert load_scene(p).lod.character_pixels == 0.0  # the distances of [lod] character
    p.write_text("[lod]\ncharacter_pixels = -1\n")
    with pytest.raises(ConfigError, match="character_pixels"):
        load_scene(p)


def test_a_bundles_pixel_bound_reaches_its_riders():
    """The manifest's lod.character_pixels (the settings step writes [lod] character_pixels) is what the
    runtime's riders take; a bundle without it: the default."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import track_scene
    from piste.world.scene import RIDER_LOD_PIXELS

    b = load_bundle(build_default_scene(0, progress=False).path)
    lod = b.manifest.setdefault("lod", {})
    lod.pop("character_pixels", None)
    assert track_scene(b).lod_pixels == RIDER_LOD_PIXELS
    lod["character_pixels"] = 0.0
    assert track_scene(b).lod_pixels == 0.0
