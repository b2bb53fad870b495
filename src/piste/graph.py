"""Connected components of an undirected graph, numpy only: the one helper that welding patch
corners (:func:`piste.terrain.net.weld_points`) and orienting a mesh's closed parts
(:func:`piste.world.scene.orient_outward`) share.

scipy.sparse.csgraph.connected_components gives the same partition, but importing scipy.sparse
alone cost a fresh process ~0.2 s before its first frame.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["connected_parts"]


def connected_parts(n_vertices: int, edges: npt.ArrayLike) -> tuple[int, np.ndarray]:
    """Connected components of a graph: ``(count, label (n_vertices,) int64)``, labels ``0..count-1``
    in the order of each part's smallest vertex.

    Min-label hooking with pointer jumping: each edge hooks the larger of its two roots under the
    smaller, then every vertex jumps straight to its root; repeated until nothing changes.

    Parameters
    ----------
    n_vertices : vertices ``0..n_vertices-1``
    edges : (e, 2) int vertex pairs (self-loops and repeats are fine)
    """
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    lab = np.arange(int(n_vertices), dtype=np.int64)
    if len(e) == 0 or n_vertices == 0:
        return int(n_vertices), lab
    a, b = e[:, 0], e[:, 1]
    while True:
        la, lb = lab[a], lab[b]
        lo = np.minimum(la, lb)
        new = lab.copy()
        np.minimum.at(new, la, lo)  # hook each root under the smaller label its edges see
        np.minimum.at(new, lb, lo)
        while True:  # pointer jumping: every vertex straight to its root
            nxt = new[new]
            if np.array_equal(nxt, new):
                break
            new = nxt
        if np.array_equal(new, lab):
            break
        lab = new
    roots, label = np.unique(lab, return_inverse=True)
    return len(roots), label.reshape(-1).astype(np.int64)
