"""Batches under a matrix / vertex budget."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.character.batches import BUDGETS, Budget, batch_mesh, check_batches, frame_bytes, make_batches
from piste.character.strips import canonical_triangles, stripify, unstripify
from piste.errors import ConfigError, ValidationError


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), nt=st.integers(1, 120), nv=st.integers(3, 80), nm=st.integers(1, 40),
       mmax=st.integers(3, 30), vmax=st.integers(3, 70), k=st.integers(1, 2), order=st.sampled_from(["cache", "given"]))
def test_every_triangle_in_exactly_one_batch_within_budget(seed, nt, nv, nm, mmax, vmax, k, order):
    rng = np.random.default_rng(seed)
    tris = rng.integers(0, nv, size=(nt, 3))
    vm = rng.integers(0, nm, size=(nv, k))
    if k == 2:
        vm[rng.random(nv) < 0.5, 1] = -1
    budget = Budget(max(mmax, 3 * k), vmax)
    batches = make_batches(tris, vm, budget, order=order)
    check_batches(batches, tris, vm, budget)  # raises if any rule is broken
    assert sum(b.n_triangles for b in batches) == nt


def test_ps2_preset_on_cesiumman(gltf_model):
    from piste.character.palette import palette

    mesh = gltf_model("CesiumMan").meshes[0]
    pal = palette(mesh, 0.1, 3)
    batches = batch_mesh(mesh, "ps2", palette=pal)
    check_batches(batches, mesh.indices, pal.index, "ps2")
    assert all(b.n_matrices <= 25 and b.n_vertices <= 55 for b in batches)
    assert 40 < len(batches) < 200
    fb = frame_bytes(batches)
    assert fb["total_bytes"] == fb["matrices"] * 48 + fb["vertices"] * 32
    # a GPU budget fits CesiumMan's 269 matrices in very few batches
    gpu = batch_mesh(mesh, "gpu256", palette=pal)
    check_batches(gpu, mesh.indices, pal.index, "gpu256")
    assert len(gpu) <= 2


def test_batch_strips_roundtrip():
    from piste.character.rider import default_rider

    mesh = default_rider().meshes[0]
    batches = batch_mesh(mesh, "ps2", step=0.25)
    strips = []
    for b in batches:
        s = stripify(b.triangles, "restart")
        assert np.array_equal(canonical_triangles(unstripify(s)), canonical_triangles(b.triangles))
        strips.append(s)
    fb = frame_bytes(batches, strips=strips)
    assert fb["vertices"] < 2 * mesh.n_triangles


def test_budget_errors():
    tris = np.array([[0, 1, 2]])
    with pytest.raises(ConfigError):
        make_batches(tris, np.array([0, 1, 2]), (2, 55))
    with pytest.raises(ConfigError):
        make_batches(tris, np.array([0, 1, 2]), "n64")
    with pytest.raises(ConfigError):
        make_batches(tris, np.array([0, 1, 2]), (25, 2))
    assert BUDGETS["ps2"] == Budget(25, 55, "ps2")
    b = make_batches(tris, np.array([0, 1, 2]), "ps2")
    b[0].triangle_ids[:] = 0
    check_batches(b, tris, np.array([0, 1, 2]), "ps2")
    with pytest.raises(ValidationError):
        check_batches(b + b, tris, np.array([0, 1, 2]), "ps2")
