"""The PS2 light-map blend ``(Cd - Cs) x As`` against true multiplication (8-bit GS arithmetic)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from piste.errors import ValidationError
from piste.lighting import modulate, ps2_blend, ps2_error_report, ps2_source


def _all_cases(cd_values):
    """Every (cd, cl, As) for one channel: cl <= As, As = max(CL) made by the green channel."""
    cl, a = np.meshgrid(np.arange(256), np.arange(256), indexing="ij")
    keep = cl <= a
    cl, a = cl[keep], a[keep]  # 32,896 pairs
    cd = np.repeat(np.asarray(cd_values), len(cl))
    cl = np.tile(cl, len(cd_values))
    a = np.tile(a, len(cd_values))
    cd3 = np.stack([cd, cd, cd], 1).astype(np.uint8)
    cl3 = np.stack([cl, a, np.zeros_like(cl)], 1).astype(np.uint8)
    return cd3, cl3


@pytest.mark.parametrize("part", range(4))
def test_exhaustive_exact_method(part):
    """All 256 x 32,896 (Cd, CL, As) combinations of a channel (in four parts): the GS result is
    within one level of true multiplication, and for As <= 128 a faithful rounding of it."""
    cd3, cl3 = _all_cases(range(part * 64, part * 64 + 64))
    cs, a = ps2_source(cd3, cl3)
    assert (a == cl3.max(1)).all()
    assert (cs <= cd3).all()
    got = ps2_blend(cd3, cs, a).astype(int)
    true = modulate(cd3, cl3).astype(int)
    assert np.abs(got - true).max() <= 1  # within one level of the rounded true product
    low = a <= 128
    exact_product = cd3.astype(float) * cl3 / 128.0
    faithful = (got == np.floor(exact_product)) | (got == true)
    assert faithful[low].all()  # for As <= 128, a faithful rounding of the exact product
    # it misses the rounded product only where that exceeds what the truncating blend can reach
    top = (cd3.astype(int) * a[:, None]) >> 7
    miss = low[:, None] & (got != true)
    assert (true[miss] > top[miss]).all()


def test_talk_formula_is_close_but_not_exact():
    cd3, cl3 = _all_cases(range(0, 256, 3))
    got = ps2_blend(cd3, *ps2_source(cd3, cl3, method="talk")).astype(int)
    true = modulate(cd3, cl3).astype(int)
    err = np.abs(got - true)
    assert 0 < err.max() <= 2
    exact = ps2_blend(cd3, *ps2_source(cd3, cl3)).astype(int)
    assert (np.abs(exact - true) <= err).all()  # the exact choice is never worse


def test_black_light_map():
    cd = np.array([[0, 100, 255], [17, 18, 19]], np.uint8)
    cl = np.zeros((2, 3), np.uint8)
    cs, a = ps2_source(cd, cl)
    assert (a == 0).all() and (cs == cd).all()
    assert (ps2_blend(cd, cs, a) == 0).all()


def test_white_light_map_is_identity_and_half_bright():
    cd = np.arange(256, dtype=np.uint8)[:, None].repeat(3, 1)
    cl = np.full_like(cd, 128)  # 128 = 1.0
    cs, a = ps2_source(cd, cl)
    assert (cs == 0).all() and (a == 128).all()
    assert (ps2_blend(cd, cs, a) == cd).all()
    assert (modulate(cd, cl) == cd).all()
    # over-bright 2x (255 ~ 1.99) saturates in both
    assert modulate(np.full((1, 3), 200, np.uint8), np.full((1, 3), 255, np.uint8)).tolist() == [[255, 255, 255]]


@settings(max_examples=200, deadline=None)
@given(
    arrays(np.uint8, (16, 3)),
    arrays(np.uint8, (16, 3)),
    arrays(np.uint8, (16,)),
)
def test_ps2_blend_is_the_gs_formula(cd, cs, a):
    got = ps2_blend(cd, cs, a).astype(int)
    for k in range(16):
        for c in range(3):
            v = ((int(cd[k, c]) - int(cs[k, c])) * int(a[k])) >> 7  # floor, like the GS
            assert got[k, c] == min(max(v, 0), 255)


@settings(max_examples=100, deadline=None)
@given(arrays(np.uint8, (32, 3)), arrays(np.uint8, (32, 3)))
def test_random_colours_within_one_level(cd, cl):
    true = modulate(cd, cl).astype(int)
    err = np.abs(ps2_blend(cd, *ps2_source(cd, cl)).astype(int) - true)
    assert err.max() <= 1
    cs, a = ps2_source(cd, cl, method="best")
    assert (a >= cl.max(1)).all() and (a.astype(int) <= np.minimum(cl.max(1).astype(int) + 3, 255)).all()
    err_best = np.abs(ps2_blend(cd, cs, a).astype(int) - true)
    assert err_best.max() <= 1 and err_best.sum() <= err.sum()


def test_error_report_over_a_scene():
    rng = np.random.default_rng(0)
    base = rng.integers(80, 256, (64, 64, 3)).astype(np.uint8)  # snow-ish base texture
    light = np.clip(rng.normal(110, 40, (64, 64, 3)), 0, 255).astype(np.uint8)
    light[:8] = [250, 40, 10]  # a saturated over-bright coloured light: channels differ a lot
    rep = ps2_error_report(base, light)
    talk = ps2_error_report(base, light, method="talk")
    assert rep["pixels"] == 64 * 64
    best = ps2_error_report(base, light, method="best")
    # the brightest channel rounding up is what would need a negative Cs
    assert rep["cs_negative_needed"] > 0
    assert max(rep["max_abs"]) <= 1 and max(talk["max_abs"]) <= 2 and max(best["max_abs"]) <= 1
    assert best["exact_fraction"] > rep["exact_fraction"] + 0.2
    assert sum(best["mean_abs"]) < sum(rep["mean_abs"])
    assert rep["by_spread"]["128-255"]["pixels"] >= 8 * 64
    assert 0 < rep["overbright_fraction"] < 1
    assert sum(talk["mean_abs"]) >= sum(rep["mean_abs"])
    assert all(set(w) == {"cd", "cl", "ps2", "true"} for w in rep["worst"])


def test_input_checks():
    with pytest.raises(ValidationError, match="0..255"):
        ps2_source(np.full((1, 3), 300), np.zeros((1, 3), np.uint8))
    with pytest.raises(ValidationError, match="RGB"):
        modulate(np.zeros((2, 4), np.uint8), np.zeros((2, 4), np.uint8))
    with pytest.raises(ValidationError, match="rounding"):
        modulate(np.zeros((1, 3), np.uint8), np.zeros((1, 3), np.uint8), rounding="up")
    with pytest.raises(ValidationError, match="method"):
        ps2_source(np.zeros((1, 3), np.uint8), np.zeros((1, 3), np.uint8), method="nope")
