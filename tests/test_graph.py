"""piste.graph.connected_parts: the same partition as scipy's connected_components, numbered by
each part's smallest vertex (terrain welding and orient_outward use it)."""

from __future__ import annotations

import numpy as np

from piste.graph import connected_parts


def test_connected_parts_equals_scipy():
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(7)
    graphs = [(1, np.zeros((0, 2), int)), (5, np.array([[0, 0], [1, 2]]))]
    graphs += [(int(n), rng.integers(0, n, (int(k), 2))) for n, k in zip(rng.integers(1, 200, 40), rng.integers(0, 300, 40))]
    n = 3000  # a long shuffled chain: one part
    graphs.append((n, np.stack([np.arange(n - 1), np.arange(1, n)], 1)[rng.permutation(n - 1)]))
    for n, e in graphs:
        k1, l1 = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
        k2, l2 = connected_parts(n, e)
        assert k2 == k1 and len(set(zip(l1.tolist(), l2.tolist()))) == k1  # the same partition
        assert l2.min() == 0 and l2.max() == k2 - 1
        first = [int(np.flatnonzero(l2 == j)[0]) for j in range(k2)]
        assert first == sorted(first)  # numbered by each part's smallest vertex
