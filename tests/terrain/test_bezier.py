import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.terrain import BEZIER_M, blend_tables, eval_power_form, evaluate
from piste.terrain.bezier import bernstein, edge_table, eval_edges, power_basis


def test_matrix_form_equals_bernstein():
    t = np.linspace(0, 1, 11)
    assert np.allclose(power_basis(t) @ BEZIER_M, bernstein(t), atol=1e-15)
    rng = np.random.default_rng(0)
    cp = rng.normal(size=(5, 4, 4, 3))
    u, v = rng.random(7), rng.random(7)
    pos = evaluate(cp, u, v, normals=False)
    assert np.allclose(pos, eval_power_form(cp, u, v), atol=1e-12)
    # direct double sum, the talk's definition
    ref = np.einsum("nijc,si,sj->nsc", cp, bernstein(u), bernstein(v))
    assert np.allclose(pos, ref, atol=1e-12)


def test_blend_tables_partition_of_unity_and_derivatives():
    for n in (4, 6, 8, 5, 17):
        t = np.linspace(0, 1, n)
        v, u = np.meshgrid(t, t, indexing="ij")
        T, Tu, Tv = blend_tables(tuple(u.ravel()), tuple(v.ravel()), "float64")
        assert T.shape == (16, n * n)
        assert np.allclose(T.sum(0), 1.0)
        assert np.allclose(Tu.sum(0), 0.0) and np.allclose(Tv.sum(0), 0.0)
    # finite-difference check of the derivative tables
    rng = np.random.default_rng(1)
    cp = rng.normal(size=(3, 4, 4, 3))
    h = 1e-6
    p0 = evaluate(cp, [0.3], [0.6], normals=False)
    pu = evaluate(cp, [0.3 + h], [0.6], normals=False)
    _, tu, _ = blend_tables((0.3,), (0.6,), "float64")
    packed = cp.reshape(3, 16, 3).transpose(0, 2, 1)
    assert np.allclose((pu - p0)[:, 0] / h, (packed @ tu)[:, :, 0], atol=1e-4)


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 20), st.integers(0, 2**31 - 1))
def test_edges_are_bit_identical_both_ways(n, seed):
    rng = np.random.default_rng(seed)
    c = (rng.normal(size=(8, 4, 3)) * 10 ** rng.uniform(-2, 4)).astype(np.float32)
    fwd = eval_edges(c, n, interior=False)
    rev = eval_edges(c[:, ::-1].copy(), n, interior=False)
    assert np.array_equal(fwd, rev[:, ::-1])
    b = edge_table(n)
    assert np.array_equal(b, b[::-1, ::-1])


def test_power_form_is_not_bit_identical_but_table_is():
    """The measured fact behind the design: the power basis breaks bit-identity on reversed edges."""
    rng = np.random.default_rng(3)
    cp = rng.normal(size=(200, 4, 4, 3)) * 3e4
    rev = cp[:, ::-1]  # the same surface with u reversed
    t = np.linspace(0, 1, 8)
    a = eval_power_form(cp, t, np.zeros(8))
    b = eval_power_form(rev, t[::-1], np.zeros(8))
    assert not np.array_equal(a, b)
    ea = eval_edges(cp[:, :, 0], 8, interior=False)
    eb = eval_edges(rev[:, :, 0], 8, interior=False)
    assert np.array_equal(ea, eb[:, ::-1])


def test_degenerate_patch_has_unit_normals():
    # a paraboloid cap z = 1 - r^2 whose u=0 side collapses to the apex (like the teapot lid)
    cp = np.zeros((1, 4, 4, 3))
    zc = [1.0, 1.0, 2.0 / 3.0, 0.0]  # 1 - u^2 in the cubic Bernstein basis
    for i in range(4):
        for j in range(4):
            ang = j / 3 * np.pi / 2
            cp[0, i, j] = (i / 3 * np.cos(ang), i / 3 * np.sin(ang), zc[i])
    t = np.linspace(0, 1, 4)
    pos, nrm = evaluate(cp, np.repeat(t, 4), np.tile(t, 4))
    assert np.allclose(np.linalg.norm(nrm, axis=-1), 1.0)
    # at the apex the limit normal is the paraboloid's axis
    apex = np.repeat(t, 4) == 0
    assert np.allclose(np.abs(nrm[0, apex, 2]), 1.0, atol=1e-3)
