"""Lights, the lighting equation, and TOML lights files."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.errors import FormatError, ValidationError
from piste.lighting import (
    AmbientLight,
    DirectionalLight,
    Lights,
    PointLight,
    SpotLight,
    default_lights,
    dumps_lights,
    light_terms,
    load_lights,
    loads_lights,
    shade,
)

UP = np.array([[0.0, 0.0, 1.0]])
ORIGIN = np.zeros((1, 3))


def test_ambient_only_is_constant():
    lights = Lights((AmbientLight((0.2, 0.4, 0.6), 0.5), AmbientLight((1, 1, 1), 0.1)))
    pts = np.random.default_rng(0).normal(size=(50, 3))
    nrm = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    c = shade(lights, pts, nrm)
    assert c.dtype == np.float32 and c.shape == (50, 3)
    np.testing.assert_allclose(c, np.broadcast_to([0.2, 0.3, 0.4], (50, 3)), rtol=1e-6)


def test_directional_lambert_and_back_faces():
    sun = DirectionalLight((0.0, -math.sin(math.radians(30)), -math.cos(math.radians(30))), (1, 1, 1), 2.0)
    lights = Lights((sun,))
    # the light travels down and towards -y: a +z normal gets cos 30, a +y normal gets sin 30
    n = np.array([[0, 0, 1.0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    c = shade(lights, np.zeros((4, 3)), n)[:, 0]
    np.testing.assert_allclose(c, [2 * math.cos(math.radians(30)), 2 * 0.5, 0.0, 0.0], rtol=1e-6)


def test_direction_is_normalised():
    assert np.isclose(np.linalg.norm(DirectionalLight((3.0, 0.0, -4.0)).direction), 1.0)
    with pytest.raises(ValidationError, match="non-zero"):
        DirectionalLight((0.0, 0.0, 0.0))


def test_point_attenuation_and_range():
    for falloff, expect_half in ((1.0, 0.5), (2.0, 0.25), (0.0, 1.0)):
        lamp = PointLight((0.0, 0.0, 5.0), (1, 1, 1), 1.0, range=10.0, falloff=falloff)
        c = shade(Lights((lamp,)), [[0, 0, 0.0], [0, 0, -5.0], [0, 0, -6.0]], [[0, 0, 1.0]] * 3)[:, 0]
        np.testing.assert_allclose(c, [expect_half, 0.0, 0.0], atol=1e-7)
    # infinite range: no attenuation
    c = shade(Lights((PointLight((0, 0, 100.0), range=math.inf),)), ORIGIN, UP)
    np.testing.assert_allclose(c, 1.0)
    with pytest.raises(ValidationError, match="range"):
        PointLight((0, 0, 0), range=-1.0)
    with pytest.raises(ValidationError, match="falloff"):
        PointLight((0, 0, 0), range=1.0, falloff=-1.0)


def test_spot_cone():
    spot = SpotLight((0, 0, 10.0), (0, 0, -1.0), (1, 1, 1), 1.0, inner_angle=10.0, outer_angle=30.0)
    lights = Lights((spot,))
    # points on the ground at angles 0, 5 (inside inner), 20 (between), 40 (outside outer) degrees
    ang = np.radians([0.0, 5.0, 20.0, 40.0])
    pts = np.stack([10.0 * np.tan(ang), np.zeros(4), np.zeros(4)], 1)
    terms = light_terms(lights, pts, np.repeat(UP, 4, 0))[:, 0]
    lam = np.cos(ang)  # n . L
    assert terms[0] == pytest.approx(lam[0]) and terms[1] == pytest.approx(lam[1])
    assert 0.0 < terms[2] < lam[2]
    assert terms[3] == 0.0
    with pytest.raises(ValidationError, match="inner_angle"):
        SpotLight((0, 0, 0), (0, 0, -1), inner_angle=40.0, outer_angle=30.0)


def test_negative_light_darkens_and_clamps_at_zero():
    amb = AmbientLight((0.5, 0.5, 0.5), 1.0)
    neg = PointLight((0, 0, 1.0), (1, 1, 1), -0.3, range=4.0, falloff=0.0)
    pts = np.array([[0, 0, 0.0], [10.0, 0, 0]])
    c = shade(Lights((amb, neg)), pts, np.repeat(UP, 2, 0))
    np.testing.assert_allclose(c[:, 0], [0.2, 0.5], rtol=1e-6)
    strong = PointLight((0, 0, 1.0), (1, 1, 1), -5.0, range=4.0, falloff=0.0)
    assert (shade(Lights((amb, strong)), pts, np.repeat(UP, 2, 0))[0] == 0.0).all()


def test_shadow_argument_masks_direct_light_only(lights):
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 30, (100, 3))
    n = rng.normal(size=(100, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    m = len(lights.direct)
    lit = shade(lights, pts, n, np.ones((100, m)))
    np.testing.assert_array_equal(lit, shade(lights, pts, n))
    dark = shade(lights, pts, n, np.zeros(100))
    np.testing.assert_allclose(dark, np.broadcast_to(np.maximum(lights.ambient_color(), 0), (100, 3)), rtol=1e-6)


def test_shade_is_batch_invariant(lights):
    """A point's colour does not depend on the batch it is shaded in (bit for bit): the baker and
    the runtime agree, and shared edge texels match."""
    rng = np.random.default_rng(2)
    pts = rng.uniform(0, 30, (301, 3))
    n = rng.normal(size=(301, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    full = shade(lights, pts, n)
    for sl in (slice(0, 1), slice(7, 64), slice(100, 301, 3)):
        np.testing.assert_array_equal(shade(lights, pts[sl], n[sl]), full[sl])


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    st.floats(-3.0, 3.0),
    st.floats(0.5, 50.0),
)
def test_shade_nonnegative_and_linear_in_intensity(pos, intensity, rng_):
    lamp = PointLight(tuple(pos), (1.0, 0.5, 0.25), intensity, range=rng_, falloff=1.0)
    amb = AmbientLight((0.1, 0.1, 0.1), 1.0)
    pts = np.random.default_rng(3).uniform(-3, 3, (20, 3))
    n = np.repeat(UP, 20, 0)
    c = shade(Lights((amb, lamp)), pts, n)
    assert (c >= 0).all()
    t = light_terms(Lights((lamp,)), pts, n)[:, 0]
    expect = np.maximum(0.1 + intensity * t[:, None] * np.array([1.0, 0.5, 0.25]), 0.0)
    np.testing.assert_allclose(c, expect, rtol=1e-5, atol=1e-6)


# ------------------------------------------------------------------------------ TOML
GOOD = """
name = "test"

[[ambient]]
color = [0.4, 0.5, 0.7]
intensity = 0.5

[[directional]]
name = "sun"
direction = [0.0, 0.0, -2.0]
color = [1.0, 0.9, 0.8]
intensity = 1.0

[[point]]
position = [1.0, 2.0, 3.0]
intensity = -0.5
range = 10.0

[[spot]]
position = [0.0, 0.0, 10.0]
direction = [0.0, 0.0, -1.0]
inner_angle = 10.0
outer_angle = 20.0
"""


def test_load_lights_file(tmp_path):
    p = tmp_path / "l.toml"
    p.write_text(GOOD)
    lights = load_lights(p)
    assert lights.name == "test"
    assert [type(x).__name__ for x in lights] == ["AmbientLight", "DirectionalLight", "PointLight", "SpotLight"]
    assert lights.direct[0].direction == (0.0, 0.0, -1.0)
    assert lights.direct[1].intensity == -0.5


def test_toml_round_trip(lights):
    again = loads_lights(dumps_lights(lights))
    assert again == lights
    assert dumps_lights(again) == dumps_lights(lights)


@pytest.mark.parametrize(
    "text, line, field, match",
    [
        ("[[point]]\nposition = [0, 0, 0]\nrange = -2.0\n", 3, "point[0].range", "range > 0"),
        ("[[ambient]]\nintensity = 1.0\n\n[[point]]\nposition = [0, 0, 0]\ncolour = [1, 1, 1]\n", 6,
         "point[0].colour", "unknown key 'colour'"),
        ("[[sun]]\ndirection = [0, 0, -1]\n", 1, "sun", "unknown light kind"),
        ("[[directional]]\ncolor = [1, 1, 1]\n", 1, "directional[0].direction", "needs 'direction'"),
        ("[[point]]\nposition = [0, 0]\n", 2, "point[0].position", "3 finite numbers"),
        ("[[spot]]\nposition = [0, 0, 1]\ndirection = [0, 0, -1]\ninner_angle = 50\nouter_angle = 20\n", None,
         None, "inner_angle <= outer_angle"),
        ("[[point]\nposition = [0, 0, 0]\n", 1, None, "not valid TOML"),
        ("[[point]]\nposition = [0, 0, 0]\n\n[[point]]\nposition = [1, 1, 1]\nintensity = \"bright\"\n", 6,
         "point[1].intensity", "expected a number"),
    ],
)
def test_toml_errors_name_line_and_key(tmp_path, text, line, field, match):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(FormatError, match=match) as info:
        load_lights(p)
    err = info.value
    assert err.path == str(p)
    if line is not None:
        assert err.line == line, str(err)
    if field is not None:
        assert err.field == field, str(err)


def test_missing_file(tmp_path):
    with pytest.raises(FormatError, match="no such file"):
        load_lights(tmp_path / "nope.toml")


def test_default_lights():
    lights = default_lights()
    kinds = [type(x) for x in lights]
    assert kinds.count(AmbientLight) >= 1 and kinds.count(DirectionalLight) == 1
    amb = lights.ambient[0].color
    assert amb[2] > amb[0]  # a coloured (blue) sky
    sun = [x for x in lights if isinstance(x, DirectionalLight)][0]
    elevation = math.degrees(math.asin(-sun.direction[2]))
    assert 5.0 < elevation < 35.0  # a low sun
    assert sum(isinstance(x, PointLight) and x.intensity > 0 for x in lights) >= 3
    assert any(x.intensity < 0 for x in lights.direct)  # the negative light
