"""SSX Tricky .pbd: decoding, byte-identical round trips, edits, nets, bad input."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from piste.errors import FormatError, ValidationError
from piste.formats.ssx import (
    PATCH_DTYPE, bezier_to_power, parse_pbd, power_to_bezier, read_pbd, records_from_net, write_pbd,
)
from piste.formats.ssx.pbd import CORNER_IJ, M
from piste.formats.ssx.synth import pbd_bytes
from piste.pipeline.ssx_synth import make_level, synthetic_net
from piste.pipeline.ssx_level import pbd_to_net


@pytest.fixture(scope="module")
def level():
    return make_level(rows=2, cols=3, seed=3, trick_every=4)


def test_record_layout_matches_the_fact_sheet():
    off = {name: PATCH_DTYPE.fields[name][1] for name in PATCH_DTYPE.names}
    assert PATCH_DTYPE.itemsize == 448
    assert off["uv"] == 0x10 and off["power"] == 0x50 and off["aabb_min"] == 0x150 and off["aabb_max"] == 0x15C
    assert off["corners"] == 0x168 and off["surface_type"] == 0x1A8 and off["visibility"] == 0x1AE
    assert off["texture"] == 0x1B0 and off["lightmap_page"] == 0x1B2 and off["unused_ids"] == 0x1B4


def test_header_and_patch_fields(level):
    p = level.pbd
    raw = p.raw
    assert raw[:3] == b"\x00\x15\x1b" and raw[3] == 1 and p.platform == 1
    assert struct.unpack_from("<I", raw, 0x08)[0] == len(p) == 6
    assert struct.unpack_from("<I", raw, 0x44)[0] == p.patch_offset == 0x90
    assert p.control_points.shape == (6, 4, 4, 3) and p.control_points.dtype == np.float64
    assert p.uv.shape == (6, 4, 2) and p.lightmap_rect.shape == (6, 4)
    assert p.trick_only.tolist() == [False, False, False, True, False, False]
    assert p.texture_index.tolist() == [0, 1, 2, 0, 1, 2]
    assert p.surface_type.tolist() == [1, 1, 1, 1, 5, 1]
    np.testing.assert_allclose(p.lightmap_rect[1], [1 / 16, 0, 1 / 16, 1 / 16])
    # the last stored coefficient is the constant term = corner cp0; the corners are cp0, cp12, cp3, cp15
    rec = p.records
    np.testing.assert_array_equal(rec["power"][:, 15, :3], rec["corners"][:, 0, :3])
    np.testing.assert_allclose(p.control_points[:, 3, 0], rec["corners"][:, 1, :3], atol=0.01)
    np.testing.assert_allclose(p.control_points[:, 0, 3], rec["corners"][:, 2, :3], atol=0.01)
    # nothing invented: every section piste does not interpret is the minimal default, empty, count 0
    assert set(p.sections) >= {"instances", "lights", "mesh_data"}
    assert all(v == b"" for k, v in p.sections.items() if k != "patches")
    assert {k: v for k, v in p.counts.items() if v} == {"patches": 6, "textures": 3}
    assert raw[p.patch_offset + 6 * 448:] == b"" and (rec["residue"] == 0).all()


def test_unedited_round_trip_is_byte_identical(level, tmp_path):
    path = level.write(tmp_path, "LVL")
    data = path.read_bytes()
    p = read_pbd(path)
    out = tmp_path / "copy.pbd"
    write_pbd(p, out)
    assert out.read_bytes() == data


def test_edit_recomputes_geometry_and_keeps_other_patches(level):
    p = parse_pbd(level.pbd.raw)
    p.control_points[2, 1, 1, 2] += 250.0
    p.texture_index[0] = 7
    p.trick_only[1] = True
    q = parse_pbd(p.to_bytes())
    assert p.edited().tolist() == [False, False, True, False, False, False]
    np.testing.assert_allclose(q.control_points[2], p.control_points[2], atol=0.05)
    assert q.texture_index[0] == 7 and q.trick_only[1] and q.records["visibility"][1] < 0
    assert q.records["aabb_max"][2, 2] >= p.control_points[2, 1, 1, 2] - 0.01
    np.testing.assert_array_equal(q.records["corners"][2, :, :3],
                                  p.control_points[2][CORNER_IJ[:, 0], CORNER_IJ[:, 1]].astype(np.float32))
    same = [0, 1, 3, 4, 5]
    np.testing.assert_array_equal(q.records["power"][same], level.pbd.records["power"][same])
    # Pbd -> bytes -> Pbd is exact
    r = parse_pbd(q.to_bytes())
    assert r.to_bytes() == q.to_bytes()
    np.testing.assert_array_equal(r.control_points, q.control_points)


def test_patch_count_cannot_change(level):
    p = parse_pbd(level.pbd.raw)
    p.control_points = p.control_points[:3]
    with pytest.raises(ValidationError, match="patch count"):
        p.to_bytes()


def test_to_net_welds_near_equal_seams(level):
    net = pbd_to_net(level.pbd)
    assert len(net) == 6 and len(net.shared_edges) == 7  # a 2 x 3 grid: 3 + 4 interior edges
    lo, hi = net.bounds
    ref = synthetic_net(2, 3, seed=3)
    np.testing.assert_allclose(lo, ref.bounds[0], atol=1e-3)
    # without a tolerance the jittered seams do not weld
    bare = pbd_to_net(level.pbd, tol=1e-9)
    assert len(bare.shared_edges) == 0


def test_records_from_net_round_trip():
    net = synthetic_net(3, 2, seed=1)
    rec = records_from_net(net)
    p = parse_pbd(pbd_bytes(rec))
    np.testing.assert_allclose(p.control_points * 0.01, net.control_points, atol=2e-4)
    back = pbd_to_net(p)
    np.testing.assert_array_equal(back.uv, net.uv)
    assert back.n_edges == net.n_edges


finite = st.floats(-2.0e4, 2.0e4, allow_nan=False, width=32)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (2, 4, 4, 3), elements=finite))
def test_bezier_power_round_trip_within_float32(cp):
    stored = bezier_to_power(cp).astype(np.float32)
    back = power_to_bezier(stored)
    # float32 storage: relative error ~ 6e-8 of the coefficients' size, amplified by M^-1 (<= 8)
    scale = max(float(np.abs(bezier_to_power(cp)).max()), 1.0)
    np.testing.assert_allclose(back, cp, atol=scale * 4e-6)


@settings(max_examples=30, deadline=None)
@given(arrays(np.float32, (3, 16, 3), elements=finite), st.integers(0, 3))
def test_pbd_bytes_pbd_exact(coef, platform):
    rec = np.zeros(3, PATCH_DTYPE)
    rec["power"][:, :, :3] = coef
    rec["power"][:, :, 3] = 1
    data = pbd_bytes(rec, platform=platform)
    p = parse_pbd(data)
    assert p.to_bytes() == data
    q = parse_pbd(p.to_bytes())
    np.testing.assert_array_equal(q.control_points, p.control_points)
    np.testing.assert_array_equal(q.records, rec)


def test_power_basis_is_m_p_mt():
    cp = np.random.default_rng(0).normal(size=(1, 4, 4, 3))
    c = np.einsum("ai,ijc,bj->abc", M, cp[0], M)
    u, v = 0.3, 0.8
    s = sum(c[i, j] * u**i * v**j for i in range(4) for j in range(4))
    from piste.terrain.bezier import evaluate

    np.testing.assert_allclose(evaluate(cp, [u], [v], normals=False)[0, 0], s, atol=1e-12)
    np.testing.assert_allclose(bezier_to_power(cp)[0, 0], c[3, 3])
    np.testing.assert_allclose(bezier_to_power(cp)[0, 15], cp[0, 0, 0])


# ----------------------------------------------------------------------------- bad input
def _corrupt(level, offset, fmt, value):
    data = bytearray(level.pbd.raw)
    struct.pack_into(fmt, data, offset, value)
    return bytes(data)


def test_truncated(level, tmp_path):
    f = tmp_path / "t.pbd"
    f.write_bytes(level.pbd.raw[:100])
    with pytest.raises(FormatError, match="truncated") as e:
        read_pbd(f)
    assert "t.pbd" in str(e.value) and e.value.field == "header"
    f.write_bytes(level.pbd.raw[: 0x90 + 448 * 3 + 10])
    with pytest.raises(FormatError, match="6 patches") as e:
        read_pbd(f)
    assert e.value.field in ("counts.patches", "offsets.instances")


def test_wrong_platform_and_version(level):
    with pytest.raises(FormatError, match="platform byte") as e:
        parse_pbd(_corrupt(level, 3, "<B", 9), "x.pbd")
    assert e.value.field == "platform" and "x.pbd" in str(e.value)
    with pytest.raises(FormatError, match="version"):
        parse_pbd(_corrupt(level, 0, "<B", 7))


def test_counts_and_offsets_past_the_end(level):
    with pytest.raises(FormatError, match="patches of 448 bytes") as e:
        parse_pbd(_corrupt(level, 0x08, "<I", 10**8))
    assert e.value.field == "counts.patches"
    with pytest.raises(FormatError, match="past the end") as e:
        parse_pbd(_corrupt(level, 64 + 4 * 6, "<I", 10**9))
    assert e.value.field == "offsets.lights"


def test_nan_coefficient_names_the_patch(level):
    data = _corrupt(level, 0x90 + 448 * 4 + 0x50 + 16 * 5 + 4, "<f", float("nan"))
    with pytest.raises(FormatError, match="patch 4: power-basis coefficient 5 \\(y\\)") as e:
        parse_pbd(data, "lvl.pbd")
    assert e.value.field == "patches.power"


def test_missing_file(tmp_path):
    with pytest.raises(FormatError, match="(?i)no such file"):
        read_pbd(tmp_path / "none.pbd")


def test_failed_write_leaves_nothing(level, tmp_path):
    p = parse_pbd(level.pbd.raw)
    p.control_points[0, 0, 0, 0] = np.nan
    out = tmp_path / "bad.pbd"
    with pytest.raises(ValidationError, match="patch 0"):
        write_pbd(p, out)
    assert list(tmp_path.iterdir()) == []


def test_to_net_widens_the_weld_for_looser_seams():
    # seams up to ~3 game units apart: the 1-unit weld would leave them open; 4 units welds them
    lv = make_level(rows=1, cols=2, seed=1, jitter=1.4)
    net = pbd_to_net(lv.pbd)
    assert len(net.shared_edges) == 1 and net.tol == pytest.approx(0.04)
    assert len(pbd_to_net(lv.pbd, tol=0.01).shared_edges) == 0  # an explicit tolerance is taken as given
    # the usual near-equal seams keep the 1-unit weld
    assert pbd_to_net(make_level(rows=1, cols=2, seed=1).pbd).tol == pytest.approx(0.01)


def test_a_level_with_no_patches_parses():
    """A ``.pbd`` whose patch count is 0 parses to an empty patch table (the fuzz run found
    ``reshape(0, -1)`` raising a raw ValueError), and ``records_from_arrays`` takes 0 patches."""
    from piste.formats.ssx.pbd import records_from_arrays

    empty = records_from_arrays(np.zeros((0, 4, 4, 3)))
    assert empty.shape == (0,) and empty.dtype == PATCH_DTYPE
    p = parse_pbd(pbd_bytes(empty))
    assert len(p.records) == 0 and p.control_points.shape == (0, 4, 4, 3)
