"""A scene rider from an SSX Tricky .mpf (``model = "ssx:RIDER.mpf"``): scene file, build with the
file's own LODs and palettes, animated render, and errors."""

from __future__ import annotations

import numpy as np
import pytest

from piste.formats.ssx.mpf import write_mpf
from piste.formats.ssx.mpf_encode import model_to_mpf

SCENE = """\
name = "mpf"

[terrain]
source = "hill.npz"

[lightmap]
res = 8

[visibility]
cell = 32.0

[[riders]]
name = "mac"
model = "{model}"
position = [60.0, 60.0]
clip = "{clip}"

[[lights]]
type = "ambient"
color = [0.6, 0.6, 0.7]
intensity = 0.5

[[lights]]
type = "directional"
direction = [0.3, 0.6, -0.6]
color = [1.0, 0.9, 0.8]
intensity = 1.0

[[cameras]]
name = "close"
eye = [60.0, 56.0, 13.0]
target = [60.0, 60.0, 12.2]
"""


def _hill(folder, n=33, spacing=4.0):
    y, x = np.mgrid[0:n, 0:n] * spacing
    z = 30.0 - 0.3 * y + 3.0 * np.sin(x / 15.0) + 2.0 * np.cos(y / 9.0)
    np.savez(folder / "hill.npz", z=z, dx=np.float64(spacing))


@pytest.fixture(scope="module")
def golden_mpf(tmp_path_factory):
    from piste.character import default_rider

    d = tmp_path_factory.mktemp("mpf")
    f, report = model_to_mpf(default_rider(0))
    write_mpf(f, d / "RIDER.mpf")
    return d / "RIDER.mpf", f


def _scene(tmp_path, golden, model="ssx:RIDER.mpf", clip="ride"):
    import shutil

    _hill(tmp_path)
    shutil.copy(golden, tmp_path / "RIDER.mpf")
    p = tmp_path / "mpf.toml"
    p.write_text(SCENE.format(model=model, clip=clip))
    return p


def test_scene_file_accepts_an_ssx_rider(tmp_path, golden_mpf):
    from piste.world.scene_file import load_scene

    s = load_scene(_scene(tmp_path, golden_mpf[0]))
    assert s.riders[0].model == str((tmp_path / "RIDER.mpf").resolve())
    assert (tmp_path / "RIDER.mpf").resolve() in s.source_files()


@pytest.mark.parametrize("model", ["ssx:MISSING.mpf", "ssx:hill.npz"])
def test_scene_file_refuses_a_bad_ssx_rider(tmp_path, golden_mpf, model):
    from piste.errors import PisteError
    from piste.world.scene_file import load_scene

    with pytest.raises(PisteError, match="model"):
        load_scene(_scene(tmp_path, golden_mpf[0], model=model))


def test_build_uses_the_files_lods_and_palettes(tmp_path, golden_mpf, piste_cache):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.world.scene_file import load_scene

    f = golden_mpf[1]
    b = load_bundle(build_scene(load_scene(_scene(tmp_path, golden_mpf[0]))).path)
    lods = b.rider_lods()
    assert [lod.n_triangles for lod in lods] == [3084, 1542, 770]
    assert [lod.palette.size for lod in lods] == [len(s.palettes) for s in f.models[:3]]
    assert all(np.all(np.isin(np.round(lod.palette.weights * 100), [0, 25, 50, 75, 100])) for lod in lods)
    assert b.rider_model().skeleton.names[:3] == ["root", "board", "pelvis"]


def test_mpf_rider_renders_animated(tmp_path, golden_mpf, gl, piste_cache):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.world.scene_file import load_scene

    scene = load_scene(_scene(tmp_path, golden_mpf[0], clip="spin"))
    b = load_bundle(build_scene(scene).path)
    p = ScenePreview(b, size=(128, 96), ctx=gl)
    try:
        a = p.render(camera_at(b, "close", 0, 2), t=0.05).astype(np.float64)
        c = p.render(camera_at(b, "close", 0, 2), t=0.55).astype(np.float64)
    finally:
        p.release()
    # without the rider: the same scene with no [[riders]]
    text = (tmp_path / "mpf.toml").read_text()
    start = text.index("[[riders]]")
    (tmp_path / "empty.toml").write_text(text[:start] + text[text.index("[[lights]]"):])
    e = load_bundle(build_scene(load_scene(tmp_path / "empty.toml")).path)
    q = ScenePreview(e, size=(128, 96), ctx=gl)
    try:
        empty = q.render(camera_at(e, "close", 0, 2), t=0.05).astype(np.float64)
    finally:
        q.release()
    covered = np.abs(a - empty).max(2) > 8
    assert covered.mean() > 0.008, "the .mpf rider is not in the picture"
    moved = np.abs(a - c).max(2) > 8
    assert moved.mean() > 0.005, "the rider does not move between t=0.05 and t=0.55 of 'spin'"


def test_partial_retarget_keeps_unmatched_bones_at_rest(tmp_path, piste_cache):
    """``model = "ssx:monster.mpf"``, ``clip = "grab"``: a rider whose arms and legs the shared
    clips cannot name (renamed ``tentacle...``) plays the clip on the bones they do name; every
    other bone keeps its rest pose in the built clip tables, every LOD's palettes name bones of
    the skeleton, and no posed LOD reaches out past its rest size (the issue's 20 m spike)."""
    from dataclasses import replace

    from piste.character import default_rider
    from piste.character.skinning import skin_exact
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.ssx_rider import load_mpf_rider
    from piste.world.scene_file import load_scene

    r = default_rider(0)
    sk = r.skeleton
    limb = ("clavicle", "arm", "hand", "shin", "foot", "toe")
    names = [("tentacle_" + n) if any(k in n for k in limb) else n for n in sk.names]
    monster = replace(r, skeleton=type(sk)(names, sk.parents, sk.rest_translation, sk.rest_rotation, sk.rest_scale,
                                           sk.inverse_bind, sk.node_index, sk.is_joint), clips={})
    f, _ = model_to_mpf(monster)
    write_mpf(f, tmp_path / "monster.mpf")
    driven = set(load_mpf_rider(tmp_path / "monster.mpf").clips["grab"].tracks)
    assert driven and not any(n.startswith("tentacle_") for n in driven)
    p = _scene(tmp_path, tmp_path / "monster.mpf", model="ssx:monster.mpf", clip="grab")
    b = load_bundle(build_scene(load_scene(p)).path)
    m = b.rider_model()
    bsk = m.skeleton
    clip = m.clips["grab"]
    rest = bsk.rest_pose()
    lods = b.rider_lods()
    for lod in lods:
        assert lod.palette.bones.max() < bsk.n_bones
    size = [np.ptp(lod.mesh.positions, axis=0).max() for lod in lods]
    undriven = [j for j, n in enumerate(bsk.names) if n not in driven]
    assert len(undriven) >= 12
    for t in np.linspace(0.0, clip.duration, 7):
        pose = clip.sample(float(t), skeleton=bsk)
        np.testing.assert_allclose(pose.translation[undriven], rest.translation[undriven], atol=1e-5)
        np.testing.assert_allclose(np.abs((pose.rotation[undriven] * rest.rotation[undriven]).sum(1)), 1.0, atol=1e-5)
        np.testing.assert_allclose(pose.scale[undriven], rest.scale[undriven], atol=1e-5)
        mats = bsk.skin_matrices(pose)
        for lod, s in zip(lods, size):
            q, _ = skin_exact(lod.mesh, mats)
            assert np.isfinite(q).all() and np.ptp(q, axis=0).max() < 1.3 * s, (t, lod.name)
