"""Per-vertex lighting (1 ambient + 3 directional): matrices, light choice, agreement with shade()."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.errors import ValidationError
from piste.lighting import AmbientLight, DirectionalLight, Lights, PointLight, SpotLight, shade
from piste.lighting.vertex import VertexLights, choose_lights, choose_lights_many, vertex_light


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_three_directionals_match_the_lighting_equation():
    lights = Lights((
        AmbientLight((0.2, 0.3, 0.4), 0.5),
        DirectionalLight((0.3, 0.2, -1.0), (1.0, 0.9, 0.8), 1.2),
        DirectionalLight((-1.0, 0.1, -0.2), (0.2, 0.4, 1.0), 0.7),
        DirectionalLight((0.0, -1.0, 0.3), (1.0, 0.2, 0.2), -0.4),  # a negative light
    ))
    rng = np.random.default_rng(1)
    n = _unit(rng, 500)
    vl = choose_lights(lights, (0.0, 0.0, 0.0))
    got = vertex_light(n, vl)
    want = shade(lights, np.zeros_like(n), n)
    np.testing.assert_allclose(got, want, atol=2e-6)


def test_matrix_form_is_D_times_n_clamped_times_C():
    vl = VertexLights(np.eye(3), np.diag([1.0, 2.0, 3.0]), (0.1, 0.1, 0.1))
    c = vertex_light(np.array([[0.6, -0.8, 0.0]]), vl)
    np.testing.assert_allclose(c[0], [0.1 + 0.6, 0.1, 0.1], atol=1e-6)


def test_strongest_three_chosen_point_and_spot_become_directions():
    far = PointLight((100.0, 0, 0), (1, 1, 1), 5.0, range=50.0, name="out of range")
    near = PointLight((3.0, 0, 0), (1, 1, 1), 1.0, range=10.0, name="near")  # attenuation 0.7
    weak = DirectionalLight((0, 0, -1), (1, 1, 1), 0.1, name="weak")
    strong = DirectionalLight((0, 0, -1), (1, 1, 1), 1.0, name="strong")
    spot = SpotLight((0, 0, 5.0), (0, 0, -1), (1, 1, 1), 2.0, range=20.0, inner_angle=10, outer_angle=20, name="spot")
    neg = PointLight((0, -2.0, 0), (1, 1, 1), -1.5, range=4.0, name="negative")  # |.| 0.75
    lights = Lights((far, near, weak, strong, spot, neg))
    vl = choose_lights(lights, (0.0, 0.0, 0.0))
    names = [lights.direct[i].name for i in vl.chosen]
    assert names == ["spot", "strong", "negative"]
    # the spot sits straight above: its direction is +z, its colour attenuated by 1 - 5/20
    np.testing.assert_allclose(vl.directions[0], [0, 0, 1], atol=1e-7)
    np.testing.assert_allclose(vl.colors[:, 0], [1.5, 1.5, 1.5], atol=1e-6)
    np.testing.assert_allclose(vl.directions[2], [0, -1, 0], atol=1e-7)
    np.testing.assert_allclose(vl.colors[:, 2], [-0.75, -0.75, -0.75], atol=1e-6)
    # outside the spot's cone it drops out
    vl2 = choose_lights(lights, (0.0, 10.0, 0.0))
    assert "spot" not in [lights.direct[i].name for i in vl2.chosen if i >= 0]


def test_fewer_lights_leave_zero_slots_and_no_lights_is_ambient():
    lights = Lights((AmbientLight((1, 1, 1), 0.25), DirectionalLight((0, 0, -1), (1, 1, 1), 1.0)))
    vl = choose_lights(lights, (0, 0, 0))
    assert list(vl.chosen) == [0, -1, -1]
    assert np.all(vl.colors[:, 1:] == 0) and np.all(vl.directions[1:] == 0)
    c = vertex_light(np.array([[0, 0, 1.0], [0, 0, -1.0]]), vl)
    np.testing.assert_allclose(c, [[1.25] * 3, [0.25] * 3], atol=1e-6)
    vl0 = choose_lights(Lights((AmbientLight((1, 0, 0), 0.5),)), (0, 0, 0))
    np.testing.assert_allclose(vertex_light(np.array([[1.0, 0, 0]]), vl0), [[0.5, 0, 0]])


def test_many_positions_agree_with_one_at_a_time():
    lights = Lights((
        AmbientLight((0.3, 0.3, 0.3), 1.0),
        PointLight((0, 0, 3), (1, 0.5, 0.2), 1.0, range=20.0, falloff=2.0),
        PointLight((10, 0, 3), (0.2, 0.5, 1.0), 1.0, range=20.0),
        SpotLight((5, 5, 8), (0, 0, -1), (1, 1, 1), 1.0, range=30.0, inner_angle=20, outer_angle=40),
        DirectionalLight((1, 1, -1), (1, 1, 1), 0.5),
    ))
    pos = np.random.default_rng(2).uniform(-5, 15, (20, 3))
    many = choose_lights_many(lights, pos)
    for i in range(len(pos)):
        one = choose_lights(lights, pos[i])
        np.testing.assert_array_equal(one.chosen, many.chosen[i])
        np.testing.assert_allclose(one.colors, many.colors[i], atol=1e-7)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_a_point_light_at_the_vertex_position_matches_shade(seed):
    """With one point light and the normals evaluated at the chosen position, the per-vertex form
    is exactly the lighting equation (attenuation and direction taken there)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-3, 3, 3)
    light = PointLight(tuple(rng.uniform(-5, 5, 3)), tuple(rng.uniform(0, 1, 3)), float(rng.uniform(-1, 2)),
                       range=float(rng.uniform(5, 30)), falloff=float(rng.choice([0.0, 1.0, 2.0])))
    lights = Lights((AmbientLight((0.1, 0.1, 0.1), 1.0), light))
    n = _unit(rng, 50)
    got = vertex_light(n, choose_lights(lights, p))
    want = shade(lights, np.broadcast_to(p, n.shape), n)
    np.testing.assert_allclose(got, want, atol=5e-6)


def test_object_space_directions():
    lights = Lights((DirectionalLight((0.2, -0.5, -1.0), (1, 1, 1), 1.0),))
    vl = choose_lights(lights, (0, 0, 0))
    a = 0.7
    r = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    n_obj = _unit(np.random.default_rng(3), 40)
    got = vertex_light(n_obj, vl.to_object_space(r))
    want = vertex_light(n_obj @ r.T, vl)
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_uniform_bytes_are_column_major():
    vl = VertexLights(np.arange(9.0).reshape(3, 3), np.eye(3), (0, 0, 0))
    u = vl.uniforms()
    cm = np.frombuffer(u["u_light_dir"], np.float32).reshape(3, 3)  # cm[col] = column
    np.testing.assert_array_equal(cm.T, np.arange(9.0).reshape(3, 3))


def test_bad_inputs():
    with pytest.raises(ValidationError):
        choose_lights(Lights(()), (0, 0, 0), k=4)
    with pytest.raises(ValidationError):
        VertexLights(np.eye(2), np.eye(3), (0, 0, 0))
    with pytest.raises(ValidationError):
        vertex_light(np.zeros((1, 3)), choose_lights_many(Lights(()), np.zeros((2, 3))))
