"""A scene rider with an ``ssx:`` model playing an SSX Tricky ``.afl`` bank's clips
(``clips_from = "x.afl"``): the scene file accepts and confines the path, the characters step
merges the bank's clips into the model's, the built rider plays them (pose off its rest pose,
rendered), and a bad bank is a one-line error naming the ``.afl``. Every file is written by
piste's encoders (mpf_encode, afl.encode_afl)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from piste.errors import PisteError
from piste.formats.ssx.afl import AflClipData, body_track, clip_channels, encode_afl, mpf_body_bones, write_afl
from piste.formats.ssx.mpf import write_mpf
from piste.formats.ssx.mpf_encode import model_to_mpf

SCENE = """\
name = "afl"

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
{extra}

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

CLIP = "bxT_NOSEGRAB"  # a name the reader resolves from its hash (afl.KNOWN_CLIP_NAMES)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """``(folder, RIDER.mpf, bank.afl)``: the default rider through the .mpf encoder, and a bank
    holding its ``spin`` clip as an AFL body track on the .mpf's body bones."""
    from piste.character import default_rider
    from piste.pipeline.ssx_rider import load_mpf_rider

    d = tmp_path_factory.mktemp("afl")
    r = default_rider(0)
    f, _ = model_to_mpf(r)
    write_mpf(f, d / "RIDER.mpf")
    model = load_mpf_rider(d / "RIDER.mpf")
    root, euler = clip_channels(r.clips["spin"], r.skeleton, mpf_body_bones(model))
    bank = encode_afl([AflClipData(CLIP, root.shape[0], [(0, body_track(root, euler))])])
    write_afl(bank, d / "bank.afl")
    return d, d / "RIDER.mpf", d / "bank.afl"


def _hill(folder, n=33, spacing=4.0):
    y, x = np.mgrid[0:n, 0:n] * spacing
    z = 30.0 - 0.3 * y + 3.0 * np.sin(x / 15.0) + 2.0 * np.cos(y / 9.0)
    np.savez(folder / "hill.npz", z=z, dx=np.float64(spacing))


def _scene(tmp_path, files, model="ssx:RIDER.mpf", extra=f'clips_from = "bank.afl"\nclip = "{CLIP}"'):
    _hill(tmp_path)
    shutil.copy(files[1], tmp_path / "RIDER.mpf")
    shutil.copy(files[2], tmp_path / "bank.afl")
    p = tmp_path / "afl.toml"
    p.write_text(SCENE.format(model=model, extra=extra))
    return p


def test_scene_file_takes_an_afl_for_an_ssx_rider(tmp_path, files):
    from piste.world.scene_file import load_scene

    s = load_scene(_scene(tmp_path, files))
    r = s.riders[0]
    assert r.clips_from == str((tmp_path / "bank.afl").resolve())
    assert r.bone_map is None and r.clip == CLIP
    assert (tmp_path / "bank.afl").resolve() in s.source_files()


@pytest.mark.parametrize("model, extra, field, words", [
    ("builtin:rider", 'clips_from = "bank.afl"', "clips_from", "ssx:<RIDER.mpf>"),
    ("ssx:RIDER.mpf", 'clips_from = "bank.afl"\nbone_map = "builtin"', "bone_map", "no bone_map"),
    ("ssx:RIDER.mpf", 'clips_from = "../outside.afl"', "clips_from", ""),
    ("ssx:RIDER.mpf", 'clips_from = "missing.afl"', "clips_from", "no such file"),
    ("ssx:RIDER.mpf", 'clips_from = "hill.npz"', "clips_from", ".afl"),
])
def test_scene_file_refuses_a_bad_afl_source(tmp_path, files, model, extra, field, words):
    from piste.world.scene_file import load_scene

    (tmp_path.parent / "outside.afl").write_bytes(files[2].read_bytes())
    with pytest.raises(PisteError, match=field) as e:
        load_scene(_scene(tmp_path, files, model=model, extra=extra))
    assert words in str(e.value)


def test_build_merges_the_afl_clips_and_the_rider_plays_one(tmp_path, files, gl, piste_cache):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.world.scene_file import load_scene

    b = load_bundle(build_scene(load_scene(_scene(tmp_path, files))).path)
    assert b.manifest["riders"][0]["clip"] == CLIP
    m = b.rider_model()
    assert CLIP in m.clips and "ride" in m.clips  # merged with the model's shared clips
    clip, sk = m.clips[CLIP], m.skeleton
    driven = [sk.get(n) for n in clip.tracks]
    assert len(driven) >= 15
    rest = sk.rest_pose()
    for t in (0.2, 0.5):  # the spin turns the body off its rest pose
        pose = clip.sample(t, skeleton=sk)
        assert np.abs(np.abs((pose.rotation[driven] * rest.rotation[driven]).sum(1)) - 1).max() > 0.05
    # it plays on screen: the picture changes between two times of the clip
    p = ScenePreview(b, size=(128, 96), ctx=gl)
    try:
        a = p.render(camera_at(b, "close", 0, 2), t=0.05).astype(np.float64)
        c = p.render(camera_at(b, "close", 0, 2), t=0.45).astype(np.float64)
    finally:
        p.release()
    assert (np.abs(a - c).max(2) > 8).mean() > 0.005, "the rider does not move through the .afl clip"


def test_an_afl_rider_defaults_to_the_banks_first_clip(tmp_path, files, piste_cache):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.world.scene_file import load_scene

    b = load_bundle(build_scene(load_scene(_scene(tmp_path, files, extra='clips_from = "bank.afl"'))).path)
    assert b.manifest["riders"][0]["clip"] == CLIP


def test_a_bad_afl_is_a_one_line_error_naming_it(tmp_path, files, piste_cache, capsys):
    from piste.cli import main

    scene = _scene(tmp_path, files)
    data = bytearray((tmp_path / "bank.afl").read_bytes())
    data[8:12] = (len(data) + 100).to_bytes(4, "little")  # the curve data offset past the end
    (tmp_path / "bank.afl").write_bytes(bytes(data))
    assert main(["build", str(scene), "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert "bank.afl" in err and "data_offset" in err and "\n" not in err and "Traceback" not in err
    (tmp_path / "bank.afl").write_bytes(b"\x4c\x11")  # shorter than the header
    assert main(["build", str(scene), "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert "bank.afl" in err and "header" in err and "\n" not in err


def test_a_bank_without_a_body_track_is_refused_by_name(tmp_path, files, piste_cache):
    from piste.formats.ssx.afl import Curve, constant
    from piste.pipeline.build import build_scene
    from piste.world.scene_file import load_scene

    scene = _scene(tmp_path, files, extra='clips_from = "bank.afl"')
    write_afl(encode_afl([AflClipData(CLIP, 4, [(1, [Curve([constant(0.0)])] * 6)])]), tmp_path / "bank.afl")
    with pytest.raises(PisteError, match="bank.afl.*body track"):
        build_scene(load_scene(scene))


def test_the_lift_of_a_hips_centred_rider_carries_to_the_afl_root(files):
    """A rider lifted to stand on its origin (the retail layout: origin at the hips) gets the same
    lift on the AFL root channels, so a bank's bind-pose root stands where the rest pose stands."""
    from piste.pipeline.sources import add_rider_clips
    from piste.pipeline.ssx_rider import load_mpf_rider

    model = load_mpf_rider(files[1])
    sk = model.skeleton
    root = int(np.flatnonzero(sk.parents < 0)[0])
    sk.rest_translation[root] += np.array([0.0, 0.75, 0.0], np.float32)  # as stand_on_origin does
    m = add_rider_clips(model, [(files[2], None)])
    tr = m.clips[CLIP].tracks[sk.names[root]]["translation"]
    plain = add_rider_clips(load_mpf_rider(files[1]), [(files[2], None)]).clips[CLIP].tracks[sk.names[root]]
    np.testing.assert_allclose(tr.values - plain["translation"].values, np.tile([0.0, 0.75, 0.0], (len(tr.values), 1)),
                               atol=1e-6)
