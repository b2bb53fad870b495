"""Quantized weight palettes (SSX Tricky blended matrices)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from piste.character.palette import palette, quantize_weights, step_units
from piste.errors import ConfigError, ValidationError


@settings(max_examples=60, deadline=None)
@given(
    w=arrays(np.float64, (20, 4), elements=st.floats(0.0, 1.0)),
    j=arrays(np.int64, (20, 4), elements=st.integers(0, 6)),
    step=st.sampled_from([0.1, 0.2, 0.25, 0.5, 1.0]),
    k=st.integers(1, 4),
)
def test_quantized_weights_sum_to_one_and_stay_within_a_step(w, j, step, k):
    bones, units = quantize_weights(j, w, step, k)
    n = step_units(step)
    assert bones.shape[1] == min(k, 4)
    assert np.all(units.sum(1) == n)
    assert np.all(units >= 0)
    # compare with the top-k renormalised weights (merged duplicate joints)
    for v in range(w.shape[0]):
        merged = {}
        for jj, ww in zip(j[v], w[v]):
            merged[jj] = merged.get(jj, 0.0) + ww
        total = sum(merged.values())
        got = {int(b): u / n for b, u in zip(bones[v], units[v]) if u > 0}
        assert len(got) <= k
        if total <= 0:
            continue
        top = sorted(merged.items(), key=lambda x: -x[1])[:k]
        ts = sum(x[1] for x in top)
        for b, q in got.items():
            ref = dict(top).get(b, 0.0) / ts
            assert abs(q - ref) <= 1.0 / n + 1e-9


def test_largest_remainder_rounding():
    j = np.array([[0, 1, 2, 3]])
    w = np.array([[0.46, 0.34, 0.20, 0.0]])
    bones, units = quantize_weights(j, w, 0.25, 3)
    # 0.46 -> 1.84 units, 0.34 -> 1.36, 0.20 -> 0.8: floors 1,1,0; two more go to .84 and .8
    assert dict(zip(bones[0].tolist(), units[0].tolist())) == {0: 2, 1: 1, 2: 1}


def test_bad_step_and_bones_raise():
    with pytest.raises(ConfigError):
        step_units(0.3)
    with pytest.raises(ConfigError):
        step_units(0.0)
    with pytest.raises(ConfigError):
        quantize_weights(np.zeros((1, 4)), np.ones((1, 4)), 0.25, 0)
    with pytest.raises(ValidationError):
        quantize_weights(np.zeros((1, 4)), np.full((1, 4), np.nan), 0.25, 3)


def test_palette_is_unique_and_reproduces_vertex_weights(gltf_model):
    mesh = gltf_model("CesiumMan").meshes[0]
    pal = palette(mesh, 0.2, 3)
    key = np.concatenate([pal.bones, pal.units], 1)
    assert np.unique(key, axis=0).shape[0] == pal.size
    assert np.allclose(pal.weights.sum(1), 1.0)
    assert pal.counts.sum() == mesh.n_vertices and np.all(pal.counts > 0)
    bones, units = quantize_weights(mesh.joints, mesh.weights, 0.2, 3)
    vb, vw = pal.vertex_weights()
    for v in range(0, mesh.n_vertices, 97):
        a = {int(b): round(float(u) * 0.2, 6) for b, u in zip(bones[v], units[v]) if u}
        b = {int(b): round(float(x), 6) for b, x in zip(vb[v], vw[v]) if x}
        assert a == b


def test_cesiumman_palette_sizes_match_reference(gltf_model):
    mesh = gltf_model("CesiumMan").meshes[0]
    sizes = [palette(mesh, s, 3).size for s in (0.1, 0.2, 0.25)]
    assert sizes == [269, 130, 94]  # /work/shared/data/README.md
    assert palette(mesh, 0.25, 1).size <= 19


def test_palette_matrices_blend_bone_matrices():
    rng = np.random.default_rng(1)
    joints = rng.integers(0, 5, (50, 4))
    weights = rng.random((50, 4))
    mesh = type("M", (), {"joints": joints, "weights": weights})()
    pal = palette(mesh, 0.1, 3)
    mats = rng.standard_normal((5, 4, 4))
    got = pal.matrices(mats)
    ref = np.einsum("pk,pkij->pij", pal.weights, mats[pal.bones])[:, :3]
    assert got.shape == (pal.size, 3, 4)
    assert np.allclose(got, ref, atol=1e-5)
    with pytest.raises(ValidationError):
        pal.matrices(mats[:2])
