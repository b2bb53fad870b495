"""SSX Tricky ``.afl`` animation banks: layout from the public facts (OpenSlope afl_pose.py), byte-identical
round trip, hostile inputs, clips playing on an encoder-written ``.mpf`` rider, glTF export, and an
optional real-file check (``PISTE_SSX_TRICKY_DIR``). Every bank here is written by the tests (by hand
from the spec, or by piste's encoder); no retail byte."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest

from piste.character.model import Clip
from piste.character.rider import default_rider
from piste.character.skinning import skin_exact
from piste.cli import main
from piste.errors import ConfigError, FormatError
from piste.formats.gltf import load_gltf
from piste.formats.ssx.afl import (
    BODY_BONE_NAMES, BODY_BONES, DEFAULT_FPS, AflClipData, Curve, afl_bytes, afl_clips, afl_hash, afl_rotation, body_track,
    clip_channels, constant, curve_bytes, encode_afl, group, mpf_body_bones, parse_afl, polynomial, read_afl, sampled,
    write_afl,
)
from piste.formats.ssx.mpf import mpf_bytes, parse_mpf, read_mpf, write_mpf
from piste.formats.ssx.mpf_encode import model_to_mpf
from piste.formats.ssx.mpf_model import SSX_TO_PISTE

from ..gltf_tools import assert_valid


# ------------------------------------------------------------------------------ helpers (spec, by hand)
def _p3(x: float) -> bytes:
    """A packed float as the spec states it: the top three bytes of the little-endian float32."""
    return struct.pack("<f", x)[1:]


def _desc(kind: int, count: int) -> bytes:
    return struct.pack("<H", (count << 4) | kind)


def _hand_bank(clips, data: bytes, pointers, pad_after_headers=b"", pad_after_pointers=b"") -> bytes:
    """A bank written straight from the spec: ``clips`` = [(key, frames, [(kind, first pointer)])]."""
    recs = []
    for key, frames, tracks in clips:
        recs.append(struct.pack("<IIBB11HI", key, 0, 255, len(tracks), frames, *([0] * 10), 0))
        for kind, first in tracks:
            recs.append(struct.pack("<IIBB11HI", 0, first, kind, 0, *([0] * 11), 0))
    ptr_off = 12 + 36 * len(recs) + len(pad_after_headers)
    data_off = ptr_off + 4 * len(pointers) + len(pad_after_pointers)
    return (struct.pack("<BBHII", 1, 0, len(recs), ptr_off, data_off) + b"".join(recs) + pad_after_headers
            + struct.pack(f"<{len(pointers)}I", *pointers) + pad_after_pointers + data)


def _hash_ref(name: str) -> int:
    h = 0
    for ch in name:
        h = (h * 16 + ord(ch)) % (1 << 32)
        top = h // (1 << 28)
        if top:
            h ^= (top << 28) >> 23
        h %= 1 << 28
    return h


def _small_bank() -> bytes:
    """One clip, a body track whose 60 channels share 3 curves: a constant, a group and 16-bit samples."""
    const = _desc(0, 0) + _p3(2.0)
    grp = (_desc(5, 2) + _desc(1, 4) + _p3(0.5) + _p3(1.0)          # 0.5 f + 1 over frames 0..3
           + _desc(7, 3) + _p3(10.0) + _p3(0.5) + struct.pack("<3H", 0, 2, 4))  # 10, 11, 12 from frame 3
    s16 = _desc(4, 3) + struct.pack("<3f", 1.0, 3.0, 7.0)
    data = const + grp + s16
    ptrs = [0, len(const), len(const) + len(grp)] + [0] * 57
    return _hand_bank([(afl_hash("frR_TURNHS"), 7, [(0, 0)])], data, ptrs)


# ------------------------------------------------------------------------------ layout and curves
def test_hash_and_packed_float_match_the_spec():
    for name in ("a", "frRL_BASECYCLEFAST", "frC_ANTIC", "x" * 40, "ZZZZZZZZZZZZ"):
        assert afl_hash(name) == _hash_ref(name)
    assert afl_hash("ab") == 0x672
    assert curve_bytes(Curve([constant(1.0)])) == b"\x00\x00" + _p3(1.0)
    assert curve_bytes(Curve([polynomial([2.0, -1.0])])) == _desc(1, 0) + _p3(2.0) + _p3(-1.0)
    # a packed float reads back with low byte 0x80
    assert constant(1.0).params[0] == struct.unpack("<f", b"\x80" + _p3(1.0))[0]


def test_hand_written_bank_reads_as_the_spec_says():
    raw = _small_bank()
    f = parse_afl(raw, "hand.afl")
    assert afl_bytes(f) == raw
    assert [(c.name, c.frames, [k for k, _ in c.tracks]) for c in f.clips] == [("frR_TURNHS", 7, [0])]
    v = f.sample("frR_TURNHS")[0]
    assert v.shape == (7, 60)
    assert (v[:, 0] == struct.unpack("<f", b"\x80" + _p3(2.0))[0]).all()  # the low byte restored as 0x80
    # group: 0.5 f + 1 over frames 0..3 (frame 3 is the shared boundary: the first segment's), then samples
    np.testing.assert_allclose(v[:, 1], [1.0, 1.5, 2.0, 2.5, 11.0, 12.0, 0.0], rtol=1e-4)
    # f32 samples with the signed-residual rule at fractional frames: nearest sample, then the residual
    # (negative below it) times the step to the next sample (none past the last)
    w = f.sample("frR_TURNHS", [0.0, 1.0, 1.4, 0.6, 1.6, 2.0, 5.0])[0][:, 2]
    np.testing.assert_allclose(w, [1.0, 3.0, 3.0 + 0.4 * 4.0, 3.0 - 0.4 * 4.0, 7.0, 7.0, 7.0], rtol=1e-6)
    assert (v[:, 3:] == v[:, [0]]).all()


def test_curve_kinds_evaluate():
    f = np.arange(6.0)
    np.testing.assert_allclose(Curve([polynomial([1.0, 2.0, 3.0, 4.0])]).evaluate(f), f ** 3 + 2 * f ** 2 + 3 * f + 4,
                               rtol=1e-4)
    s8 = sampled([0.0, 1.0, 3.0], bits=8)
    assert s8.kind == 6 and s8.samples.dtype == np.uint8
    np.testing.assert_allclose(Curve([s8]).evaluate([0, 1, 2, 9]), [0, 1, 3, 3], atol=3 / 255 + 1e-4)
    g = group([constant(5.0, 2), polynomial([1.0, 0.0], 3)])  # 5 at 0..1, then f_local at 1..3
    np.testing.assert_allclose(g.evaluate([0, 1, 2, 3, 4]), [5, 5, 1, 2, 0], rtol=1e-4)


def test_encoder_round_trip_byte_identical_and_pads_kept():
    F = 12
    root = np.stack([np.linspace(0, 50, F), np.zeros(F), np.full(F, 90.0)], 1)
    e = np.zeros((F, BODY_BONES, 3))
    e[:, 4, 1] = np.sin(np.arange(F) / 3)
    board = [Curve([constant(0.0)]), group([polynomial([0.1, 0.0, 1.0], 4), sampled([1, 2, 3], 32)]),
             Curve([sampled(np.cos(np.arange(F)), 8)]), Curve([polynomial([1.0, 0.0, 0.0, 0.0])]),
             Curve([constant(3.0)]), Curve([constant(0.0)])]
    f = encode_afl([AflClipData("frRL_CROUCHCYCLE", F, [(0, body_track(root, e)), (1, board)]),
                    AflClipData("mine", 3, [(0, body_track(root[:3], e[:3]))])])
    raw = afl_bytes(f)
    g = parse_afl(raw, "x.afl", names=["mine"])
    assert afl_bytes(g) == raw
    assert [c.name for c in g.clips] == ["frRL_CROUCHCYCLE", "mine"]
    assert len(set(g.pointers.tolist())) < len(g.pointers)  # identical curves stored once
    for off, cv in g.curves.items():  # every decoded curve re-encodes to the bytes it came from
        b = curve_bytes(cv)
        assert g.data[off:off + len(b)] == b
    body, brd = g.sample("frRL_CROUCHCYCLE")
    np.testing.assert_allclose(body[:, 0], root[:, 0], atol=0.01)
    np.testing.assert_allclose(body[:, 3 + 3 * 4 + 1], e[:, 4, 1], atol=1e-4)
    assert brd.shape == (F, 6)
    # bytes between the tables survive
    raw2 = _hand_bank([(afl_hash("a"), 2, [(0, 0)])], _desc(0, 0) + _p3(1.0), [0] * 60, b"\x11" * 5, b"\x22\x33")
    assert afl_bytes(parse_afl(raw2)) == raw2
    assert parse_afl(raw2).pads == (b"\x11" * 5, b"\x22\x33")


def test_encoder_header_as_retail_files_hold_it():
    f = encode_afl([AflClipData("bxRL_CROUCHCYCLE", 9, [(0, [Curve([constant(0.0)])] * 60)])])
    raw = afl_bytes(f)
    console, unknown, n, ptr_off, data_off = struct.unpack_from("<BBHII", raw)
    assert (console, unknown, n, ptr_off, data_off) == (76, 17, 2, 12 + 72, 12 + 72 + 240)
    key, first, kind, related, *fields, tail = struct.unpack_from("<IIBB11HI", raw, 12)
    assert (key, kind, related, fields[0]) == (afl_hash("bxRL_CROUCHCYCLE"), 255, 1, 9)
    assert fields[1:] == [0xFFFF] * 10 and tail == 0  # no events
    assert struct.unpack_from("<IIBB", raw, 48) == (0, 0, 0, 0)
    assert parse_afl(raw).clips[0].name == "bxRL_CROUCHCYCLE"  # a known name resolves from its hash


def test_write_and_read_file(tmp_path):
    f = parse_afl(_small_bank())
    write_afl(f, tmp_path / "b.afl")
    assert (tmp_path / "b.afl").read_bytes() == _small_bank()
    assert read_afl(tmp_path / "b.afl", names=["frR_TURNHS"]).clips[0].frames == 7


# ------------------------------------------------------------------------------ hostile input
def test_every_truncation_is_a_format_error():
    raw = _small_bank()
    for n in range(len(raw)):
        with pytest.raises(FormatError) as e:
            parse_afl(raw[:n], "cut.afl")
        assert "cut.afl" in str(e.value) and e.value.field


@pytest.mark.parametrize("patch, field", [
    (lambda b: b[:2] + struct.pack("<H", 65535) + b[4:], "header_count"),
    (lambda b: b[:4] + struct.pack("<I", 5) + b[8:], "pointer_offset"),
    (lambda b: b[:8] + struct.pack("<I", 1 << 31) + b[12:], "data_offset"),
    (lambda b: b[:12 + 36 + 4] + struct.pack("<I", 10 ** 6) + b[12 + 36 + 8:], "headers[1].pointer_index"),
    (lambda b: b[:12 + 9] + b"\x07" + b[12 + 10:], "headers[0].related"),
])
def test_huge_counts_and_offsets_refused(patch, field):
    with pytest.raises(FormatError) as e:
        parse_afl(patch(_small_bank()), "bad.afl")
    assert e.value.field == field and "bad.afl" in str(e.value)


@pytest.mark.parametrize("curve, field, words", [
    (_desc(4, 4095) + b"\0" * 8, "curve[0].count", "needs"),                  # 4095 samples in 10 bytes
    (_desc(0, 0) + b"\x00\xc0\x7f", "curve[0].values", "finite"),            # NaN packed float
    (_desc(4, 1) + struct.pack("<f", float("inf")), "curve[0].values", "finite"),
    (_desc(9, 0) + b"\0" * 8, "curve[0].kind", "kind"),
    (_desc(5, 1) + _desc(5, 1) + _desc(0, 1) + _p3(1.0), "curve[0].segment[0].kind", "nested"),
    (_desc(5, 1) + _desc(0, 0) + _p3(1.0), "curve[0].segment[0].count", "duration"),
    (_desc(7, 0) + b"\0" * 6, "curve[0].count", "at least one sample"),
    (_desc(5, 4095) + _desc(0, 1) + _p3(1.0), "curve[0].segment[1].descriptor", "past the end"),
])
def test_hostile_curves_refused(curve, field, words):
    raw = _hand_bank([(1, 3, [(0, 0)])], curve, [0] * 60)
    with pytest.raises(FormatError) as e:
        parse_afl(raw, "bad.afl")
    assert e.value.field == field and words in str(e.value)


def test_pointer_past_the_data_and_unknown_track_kind():
    raw = _hand_bank([(1, 3, [(0, 0)])], _desc(0, 0) + _p3(1.0), [0] * 59 + [1000])
    with pytest.raises(FormatError, match="past the end") as e:
        parse_afl(raw, "bad.afl")
    assert e.value.field == "curve[59]"
    f = parse_afl(_hand_bank([(1, 3, [(3, 0)])], b"", []))  # kind 3 is not a documented track: kept, noted
    assert f.clips[0].tracks == [(3, None)] and "kind 3" in f.notes[0]


def test_huge_frame_counts_refused_before_baking():
    raw = _hand_bank([(k, 65535, [(0, 0)]) for k in range(5)], _desc(0, 0) + _p3(1.0), [0] * 60)
    f = parse_afl(raw, "big.afl")  # 5 clips x 65,535 frames x 60 channels from a 1 kB file
    sk = default_rider(0).skeleton
    with pytest.raises(FormatError, match="limit") as e:
        afl_clips(f, sk)
    assert e.value.field == "frames"
    with pytest.raises(ConfigError):
        afl_clips(f, sk, fps=float("nan"))


def test_overflowing_polynomial_is_a_format_error():
    raw = _hand_bank([(1, 200, [(0, 0)])], _desc(3, 0) + _p3(3e38) * 4, [0] * 60)
    with pytest.raises(FormatError, match="non-finite"):
        afl_clips(parse_afl(raw, "inf.afl"), default_rider(0).skeleton)


def test_read_refuses_a_folder(tmp_path):
    with pytest.raises(FormatError):
        read_afl(tmp_path)


# ------------------------------------------------------------------------------ clips on an .mpf rider
@pytest.fixture(scope="module")
def rider():
    r = default_rider(0)
    f, _ = model_to_mpf(r)
    mpf = parse_mpf(mpf_bytes(f))
    return r, mpf, mpf.to_model()


def _rot(axis: int, a):
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(np.shape(a) + (3, 3))
    i, j = [(1, 2), (0, 2), (0, 1)][axis]
    m[..., axis, axis] = 1
    m[..., i, i], m[..., j, j] = c, c
    m[..., i, j], m[..., j, i] = (-s, s) if axis != 1 else (s, -s)
    return m


def _reference_joints(bones, channels):
    """Joint positions (cm, .mpf axes) per the public facts: local Rz(-z) Ry(-y) Rx(-x) of each
    bone's triple, the root at the root channels, children at parent + parent rotation x bind
    translation (written independently of piste's module)."""
    n = len(bones)
    pos, rot = np.zeros((n, 3)), np.zeros((n, 3, 3))
    for i, b in enumerate(bones):
        x, y, z = channels[3 + 3 * i:6 + 3 * i]
        r = _rot(2, -z) @ _rot(1, -y) @ _rot(0, -x)
        p = int(b["parent_bone"])
        if p < 0:
            pos[i], rot[i] = channels[:3], r
        else:
            pos[i] = pos[p] + rot[p] @ b["translation"].astype(np.float64)
            rot[i] = rot[p] @ r
    return pos


def test_afl_clip_poses_the_mpf_rider_as_the_facts_say(rider):
    r, mpf, model = rider
    bones = mpf_body_bones(model)
    assert bones == mpf.models[0].bone_names
    clip = r.clips["ride"]  # without the pelvis translation (an AFL body track moves only the root)
    clip = Clip("ride", clip.duration, {k: {p: t for p, t in v.items() if p != "translation"}
                                        for k, v in clip.tracks.items()}, skeleton=clip.skeleton)
    root, euler = clip_channels(clip, r.skeleton, bones)
    afl = encode_afl([AflClipData("frRL_BASECYCLEFAST", root.shape[0], [(0, body_track(root, euler))])])
    got = afl_clips(afl, model.skeleton, bones)["frRL_BASECYCLEFAST"]
    assert got.duration == pytest.approx(clip.duration)
    ch = afl.sample(afl.clips[0])[0]
    a = SSX_TO_PISTE
    driven = [model.skeleton.get(n) for n in bones[:BODY_BONES]]
    rest = model.skeleton.rest_pose()
    moved = 0
    for frame in (0, 17, 45, ch.shape[0] - 1):
        pose = got.sample(frame / DEFAULT_FPS, model.skeleton)
        world = model.skeleton.world_matrices(pose)[:, :3, 3]
        ref = _reference_joints(mpf.models[0].bones[:BODY_BONES], ch[frame])
        np.testing.assert_allclose((world[driven] @ a) / 0.01, ref, atol=0.05)  # cm
        # the source clip's joints agree (16-bit quantisation), the undriven bones keep their rest pose
        src = r.skeleton.world_matrices(clip.sample(frame / DEFAULT_FPS, r.skeleton))[:, :3, 3]
        np.testing.assert_allclose(world[driven], src[driven], atol=1e-3)
        undriven = [j for j in range(model.skeleton.n_bones) if j not in driven]
        assert undriven and np.array_equal(pose.rotation[undriven], rest.rotation[undriven])
        assert np.array_equal(pose.translation[undriven], rest.translation[undriven])
        moved += int(np.abs(pose.rotation[driven] - rest.rotation[driven]).max() > 1e-3)
    assert moved >= 3


def test_unmatched_bones_keep_rest_and_mesh_stays_bounded(rider):
    _, _, model = rider
    F = 20
    e = np.zeros((F, BODY_BONES, 3))
    e[:, :, 0] = np.linspace(0, 0.6, F)[:, None]
    root = np.tile([0.0, 0.0, 100.0], (F, 1))
    afl = encode_afl([AflClipData("c", F, [(0, body_track(root, e))])])
    names = mpf_body_bones(model)
    part = [n if i % 2 == 0 else "no_such_bone" for i, n in enumerate(names)]  # a partial match
    clip = afl_clips(afl, model.skeleton, part)["c"]
    assert set(clip.tracks) == {n for n in part[:BODY_BONES] if n != "no_such_bone"}
    pose = clip.sample(clip.duration, model.skeleton)
    rest = model.skeleton.rest_pose()
    free = [model.skeleton.get(n) for n in model.skeleton.names if n not in clip.tracks]
    assert np.array_equal(pose.rotation[free], rest.rotation[free])
    pos, _ = skin_exact(model.meshes[0], model.skeleton.skin_matrices(pose))
    bind = model.meshes[0].positions
    assert np.isfinite(pos).all()
    assert np.ptp(pos, axis=0).max() < 2.0 * np.ptp(bind, axis=0).max()  # no spike
    assert np.abs(pos - bind).max() > 0.05  # and it does move


def test_bind_angles_as_a_clip_give_the_bind_pose(rider):
    """The .afl and the .mpf bind pose share one Euler convention (Rz(-z) Ry(-y) Rx(-x)): a clip holding
    each bone's bind angles and the root's bind translation poses the rider exactly at its bind pose."""
    _, mpf, _ = rider
    mpf = parse_mpf(mpf_bytes(mpf))
    for s in mpf.models:  # bind rotations that tell the two conventions apart (the default rider's are ~0)
        if len(s.bones):
            s.bones["rotation"] = np.random.default_rng(5).uniform(-0.8, 0.8, s.bones["rotation"].shape)
    mpf = parse_mpf(mpf_bytes(mpf))
    model = mpf.to_model()
    bones = mpf.models[0].bones[:BODY_BONES]
    ch = np.concatenate([bones["translation"][0], bones["rotation"].reshape(-1)]).astype(np.float64)
    curves = [Curve([constant(v)]) for v in ch]
    afl = encode_afl([AflClipData("bind", 2, [(0, curves)])])
    clip = afl_clips(afl, model.skeleton, mpf_body_bones(model))["bind"]
    world = model.skeleton.world_matrices(clip.sample(0.0, model.skeleton))
    np.testing.assert_allclose(world, model.skeleton.bind_pose_world(), atol=1e-3)


def test_board_track_drives_the_board_bone(rider):
    _, _, model = rider
    sk = model.skeleton
    F = 6
    e = np.zeros((F, BODY_BONES, 3))
    e[:, 0, 2] = np.linspace(0, 0.5, F)  # the root turns: the board's local transform must undo it
    root = np.tile([3.0, 4.0, 95.0], (F, 1))
    bp = np.stack([np.linspace(0, 20, F), np.zeros(F), np.full(F, 2.0)], 1)
    be = np.stack([np.zeros(F), np.linspace(0, 0.3, F), np.linspace(0, -0.4, F)], 1)
    board = [Curve([sampled(bp[:, i], 32)]) for i in range(3)] + [Curve([sampled(be[:, i], 32)]) for i in range(3)]
    afl = encode_afl([AflClipData("c", F, [(0, body_track(root, e)), (1, board)])])
    bones = [None if n == "board" else n for n in mpf_body_bones(model)]  # the body track leaves "board" alone
    clip = afl_clips(afl, sk, bones)["c"]
    assert set(clip.tracks["board"]) == {"translation", "rotation"}
    a = SSX_TO_PISTE
    for frame in range(F):
        w = sk.world_matrices(clip.sample(frame / DEFAULT_FPS, sk))[sk.get("board")]
        np.testing.assert_allclose(w[:3, 3], a @ bp[frame] * 0.01, atol=1e-6)
        np.testing.assert_allclose(w[:3, :3], a @ afl_rotation(be[frame]) @ a.T, atol=1e-6)
    # when the body track drives "board" (piste's encoder puts it among the first 19 bones) the board track does not
    assert set(afl_clips(afl, sk, mpf_body_bones(model))["c"].tracks["board"]) == {"rotation"}


# ------------------------------------------------------------------------------ CLI and glTF
def test_cli_export_with_afl_clips_validates(tmp_path, rider, capsys):
    _, mpf, model = rider
    write_mpf(mpf, tmp_path / "R.mpf")
    F = 30
    e = np.zeros((F, BODY_BONES, 3))
    e[:, 3, 0] = np.linspace(0, 1, F)
    e[:, 10, 2] = np.sin(np.arange(F) / 5)
    root = np.stack([np.linspace(0, 10, F), np.zeros(F), np.full(F, 90.0)], 1)
    board = [Curve([constant(0.0)])] * 6
    write_afl(encode_afl([AflClipData("frR_TURNHS", F, [(0, body_track(root, e))]),
                          AflClipData("frC_ANTIC", 4, [(0, body_track(root[:4], e[:4])), (1, board)]),
                          AflClipData("boardonly", 4, [(1, board)])]), tmp_path / "bank.afl")
    assert main(["mpf", "export", str(tmp_path / "R.mpf"), "--clips", str(tmp_path / "bank.afl"),
                 str(tmp_path / "R.glb")]) == 0
    out = capsys.readouterr().out
    assert "2 clips" in out and "19 of the model's 25 bones driven" in out and "no body track" in out
    assert_valid(tmp_path / "R.glb")
    m = load_gltf(tmp_path / "R.glb")
    assert set(m.clips) == {"frR_TURNHS", "frC_ANTIC"}
    assert m.clips["frR_TURNHS"].duration == pytest.approx((F - 1) / DEFAULT_FPS, abs=1e-4)


def test_cli_bad_afl_is_one_line(tmp_path, rider, capsys):
    _, mpf, _ = rider
    write_mpf(mpf, tmp_path / "R.mpf")
    (tmp_path / "bad.afl").write_bytes(_small_bank()[:40])
    assert main(["mpf", "export", str(tmp_path / "R.mpf"), "--clips", str(tmp_path / "bad.afl"),
                 str(tmp_path / "R.glb")]) != 0  # the CLI's runtime-error status
    err = capsys.readouterr().err
    assert "bad.afl" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "R.glb").exists()


# ------------------------------------------------------------------------------ the user's own files
@pytest.mark.skipif(not os.environ.get("PISTE_SSX_TRICKY_DIR"),
                    reason="set PISTE_SSX_TRICKY_DIR to a folder holding your own SSX Tricky .afl files")
def test_real_afl_files_read_and_write_back():
    root = Path(os.environ["PISTE_SSX_TRICKY_DIR"])
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() == ".afl" and p.is_file())
    if not files:
        pytest.skip(f"no .afl files under PISTE_SSX_TRICKY_DIR={root}")
    sk = default_rider(0).skeleton
    for path in files:
        f = read_afl(path)
        assert afl_bytes(f) == path.read_bytes(), f"{path.name}: not written back byte for byte"
        assert f.clips, f"{path.name}: no named clips"
        for c in f.clips:
            for vals in f.sample(c):
                assert vals is None or np.isfinite(vals).all(), f"{path.name}: {c.name}"
        clips = afl_clips(f, sk)
        assert all(np.isfinite(tr.values).all() for c in clips.values() for bt in c.tracks.values()
                   for tr in bt.values())


@pytest.mark.skipif(not os.environ.get("PISTE_SSX_TRICKY_DIR"),
                    reason="set PISTE_SSX_TRICKY_DIR to a folder holding your own SSX Tricky .mpf rider files")
def test_real_body_models_take_a_body_track():
    """The user's own retail body models: their 19 body bones are the documented body-track order, and a
    body track holding each bone's bind angles (written from the spec, not game data) poses them at bind."""
    root = Path(os.environ["PISTE_SSX_TRICKY_DIR"])
    bodies = []
    for path in sorted(p for p in root.rglob("*") if p.suffix.lower() == ".mpf" and p.is_file()):
        f = read_mpf(path)
        if any(s.bone_names == list(BODY_BONE_NAMES) for s in f.models):
            bodies.append(f)
    if not bodies:
        pytest.skip(f"no .mpf body model (19 bones hips .. r_foot) under PISTE_SSX_TRICKY_DIR={root}")
    for f in bodies:
        model = f.to_model()
        assert mpf_body_bones(model) == list(BODY_BONE_NAMES)
        s = next(s for s in f.models if s.bone_names == list(BODY_BONE_NAMES))
        ch = np.concatenate([s.bones["translation"][0], s.bones["rotation"].reshape(-1)]).astype(np.float64)
        afl = encode_afl([AflClipData("bind", 2, [(0, [Curve([constant(v)]) for v in ch])])])
        clip = afl_clips(afl, model.skeleton)["bind"]  # default bones: the documented order
        world = model.skeleton.world_matrices(clip.sample(0.0, model.skeleton))
        np.testing.assert_allclose(world, model.skeleton.bind_pose_world(), atol=1e-3, err_msg=f.path)


def test_mpf_body_bones_of_a_model_without_a_skeleton_is_a_clear_error():
    """Was an AttributeError on None (found by mypy); now a ValidationError that says what is missing."""
    from types import SimpleNamespace

    from piste.errors import ValidationError

    with pytest.raises(ValidationError, match="no skeleton"):
        mpf_body_bones(SimpleNamespace(files=[], skeleton=None))
