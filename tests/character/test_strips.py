"""Triangle strips decode back to exactly the same oriented triangles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.character.strips import RESTART, canonical_triangles, strip_stats, stripify, unstripify
from piste.errors import ConfigError


def _grid(nx, ny):
    i = np.arange(ny - 1)[:, None] * nx
    j = np.arange(nx - 1)[None, :]
    a = i + j
    return np.concatenate([np.stack([a, a + nx, a + 1], -1).reshape(-1, 3),
                           np.stack([a + 1, a + nx, a + nx + 1], -1).reshape(-1, 3)])


def test_unstripify_convention():
    # odd triangles of a strip are read as (s[i+1], s[i], s[i+2]) so every triangle keeps its winding
    assert unstripify([0, 1, 2, 3]).tolist() == [[0, 1, 2], [2, 1, 3]]
    assert unstripify([0, 1, 2, RESTART, 3, 4, 5, 6]).tolist() == [[0, 1, 2], [3, 4, 5], [5, 4, 6]]
    assert unstripify([0, 1, 2, 2, 2, 3, 3, 4, 5]).tolist() == [[0, 1, 2], [3, 4, 5]]
    assert stripify([[0, 1, 2], [3, 4, 5]], "degenerate").tolist() == [0, 1, 2, 2, 2, 3, 3, 4, 5]


@pytest.mark.parametrize("join", ["restart", "degenerate", None])
@pytest.mark.parametrize("method", ["greedy", "meshopt"])
def test_grid_strips_roundtrip(join, method):
    tris = _grid(9, 7)
    s = stripify(tris, join, method)
    assert np.array_equal(canonical_triangles(unstripify(s)), canonical_triangles(tris))
    if join is not None:
        stats = strip_stats(tris, s)
        assert stats["triangles"] == len(tris)
        assert stats["vertices_per_triangle"] < 2.0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 60), join=st.sampled_from(["restart", "degenerate"]),
       method=st.sampled_from(["greedy", "meshopt"]))
def test_random_triangle_soups_roundtrip(seed, n, join, method):
    rng = np.random.default_rng(seed)
    # random subsets of a grid (shared edges, both windings present) plus random triangles
    g = _grid(6, 6)
    tris = g[rng.choice(len(g), size=min(n, len(g)), replace=False)]
    extra = rng.integers(0, 40, size=(n // 3, 3))
    tris = np.concatenate([tris, extra])
    s = stripify(tris, join, method)
    assert np.array_equal(canonical_triangles(unstripify(s)), canonical_triangles(tris))


def test_rider_strips_are_efficient():
    from piste.character.rider import default_rider

    tris = default_rider().meshes[0].indices
    s = stripify(tris, "restart")
    assert np.array_equal(canonical_triangles(unstripify(s)), canonical_triangles(tris))
    assert strip_stats(tris, s)["vertices_per_triangle"] < 1.5


def test_bad_arguments():
    with pytest.raises(ConfigError):
        stripify(_grid(3, 3), join="fan")
    with pytest.raises(ConfigError):
        stripify(_grid(3, 3), method="nvtristrip")
