"""Triangle strips: a greedy stripifier (and meshoptimizer's as a peer), joining by restart or
degenerate triangles, decoding back to triangles, and vertices-sent-per-triangle figures.

Strip convention (OpenGL, PS2 GS, meshoptimizer): in one strip ``s``, triangle ``i`` is
``(s[i], s[i+1], s[i+2])`` for even ``i`` and ``(s[i+1], s[i], s[i+2])`` for odd ``i``, so every
triangle keeps its winding. A *restart* marker (``RESTART = -1`` here, ``0xFFFFFFFF`` in an index
buffer, the ADC bit on the PS2) ends a strip and resets the parity; *degenerate* joining repeats
the last vertex of one strip and the first of the next (plus one more when needed to keep the
parity), and triangles with a repeated index draw nothing and are dropped by decoders.

API
---
::

    - ``stripify(triangles, join="restart"|"degenerate"|None, method="greedy"|"meshopt") ->
      (n,) int64`` strip (with ``RESTART`` markers) or, for ``join=None``, a list of strips
    - ``unstripify(strip) -> (t, 3) int64`` triangles (degenerate ones dropped)
    - ``strip_stats(triangles, strip) -> dict``: strips, triangles, indices, vertices sent per
      triangle for indexed and non-indexed strips
    - ``RESTART``
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, ValidationError

__all__ = ["stripify", "unstripify", "strip_stats", "RESTART", "JOINS", "METHODS"]

RESTART = -1
JOINS = ("restart", "degenerate", None)
METHODS = ("greedy", "meshopt")


def _as_triangles(triangles: npt.ArrayLike) -> np.ndarray:
    t = np.asarray(triangles)
    if t.ndim != 2 or t.shape[1] != 3:
        t = t.reshape(-1, 3)
    t = t.astype(np.int64)
    if t.size and t.min() < 0:
        raise ValidationError("triangle indices must be >= 0")
    return t


def _nondegenerate(t: np.ndarray) -> np.ndarray:
    ok = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
    return t[ok]


def _greedy_strips(tris: np.ndarray) -> list:
    """Greedy strips over ``tris (t, 3)`` (non-degenerate), visited in the given order.

    Each strip starts at the first unused triangle, tries its three rotations and keeps the one
    that grows the longest strip; a strip grows while an unused triangle holds the directed edge
    the parity asks for (``a -> b`` after an even triangle ending ``..a, b``, ``b -> a`` after an
    odd one). Construction-time code: a Python loop over triangles of one batch or mesh.
    """
    n = tris.shape[0]
    edge: dict[tuple[int, int], list[int]] = {}
    for t in range(n):
        a, b, c = (int(x) for x in tris[t])
        for e in ((a, b), (b, c), (c, a)):
            edge.setdefault(e, []).append(t)
    used = np.zeros(n, bool)

    def find(a: int, b: int) -> int:
        for t in edge.get((a, b), ()):
            if not used[t]:
                return t
        return -1

    def grow(seq: list[int], taken: set[int]) -> tuple[list[int], set[int]]:
        # seq: list of vertices; taken: triangles claimed by this trial (set)
        while True:
            i = len(seq) - 3 + 1  # index of the next triangle
            a, b = seq[-2], seq[-1]
            cand = -1
            for t in edge.get((a, b) if i % 2 == 0 else (b, a), ()):
                if not used[t] and t not in taken:
                    cand = t
                    break
            if cand < 0:
                return seq, taken
            x, y, z = (int(v) for v in tris[cand])
            # third vertex: the one not on the shared edge
            c = z if {x, y} == {a, b} else (x if {y, z} == {a, b} else y)
            seq.append(c)
            taken.add(cand)

    strips = []
    for start in range(n):
        if used[start]:
            continue
        a, b, c = (int(x) for x in tris[start])
        best: tuple[list[int], set[int]] | None = None
        for rot in ((a, b, c), (b, c, a), (c, a, b)):
            seq, taken = grow(list(rot), {start})
            if best is None or len(seq) > len(best[0]):
                best = (seq, taken)
        assert best is not None
        seq, taken = best
        used[list(taken)] = True
        strips.append(np.array(seq, dtype=np.int64))
    return strips


def _meshopt_strip(tris: np.ndarray, restart: bool) -> np.ndarray | None:
    """meshoptimizer's ``meshopt_stripify`` through its bundled library; None if unavailable."""
    try:
        import ctypes

        from meshoptimizer._loader import lib

        fn = lib.meshopt_stripify
        bound = lib.meshopt_stripifyBound
    except Exception:  # pragma: no cover - depends on the wheel's internals
        return None
    fn.argtypes = [ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                   ctypes.c_size_t, ctypes.c_uint]
    fn.restype = ctypes.c_size_t
    bound.argtypes = [ctypes.c_size_t]
    bound.restype = ctypes.c_size_t
    import meshoptimizer

    src = np.ascontiguousarray(tris.reshape(-1), dtype=np.uint32)
    nv = int(src.max()) + 1 if src.size else 0
    idx = np.zeros_like(src)  # meshopt_stripify wants a strip-friendly triangle order first
    meshoptimizer.optimize_vertex_cache_strip(idx, src, src.size, nv)
    if restart and nv >= 0xFFFFFFFF:  # pragma: no cover
        return None
    out = np.zeros(int(bound(idx.size)) + 4, np.uint32)
    marker = 0xFFFFFFFF if restart else 0
    count = fn(out.ctypes.data_as(ctypes.POINTER(ctypes.c_uint)), idx.ctypes.data_as(ctypes.POINTER(ctypes.c_uint)),
               idx.size, nv, marker)
    s = out[:count].astype(np.int64)
    if restart:
        s[out[:count] == 0xFFFFFFFF] = RESTART
    return s


def _join(strips: list, join: str) -> np.ndarray:
    if not strips:
        return np.zeros(0, np.int64)
    if join == "restart":
        parts = []
        for k, s in enumerate(strips):
            if k:
                parts.append(np.array([RESTART]))
            parts.append(s)
        return np.concatenate(parts)
    parts = [strips[0]]
    length = len(strips[0])
    for s in strips[1:]:
        bridge = [parts[-1][-1]] + ([parts[-1][-1]] if length % 2 else []) + [s[0]]
        parts.append(np.array(bridge, dtype=np.int64))
        parts.append(s)
        length += len(bridge) + len(s)
    return np.concatenate(parts)


def stripify(triangles: npt.ArrayLike, join: str | None = "restart",
             method: str = "greedy") -> np.ndarray | list[np.ndarray]:
    """Turn ``triangles (t, 3)`` into triangle strips that keep every triangle's winding.

    Parameters
    ----------
    triangles : (t, 3) int     indexed triangles (degenerate ones are dropped: they draw nothing)
    join : "restart" | "degenerate" | None
        how strips are joined into one index sequence (``RESTART`` markers or repeated indices);
        None returns the list of separate strips ``[(n_i,) int64, ...]``
    method : "greedy" | "meshopt"
        piste's greedy stripifier (visits triangles in the given order), or meshoptimizer's
        ``optimize_vertex_cache_strip`` + ``meshopt_stripify`` (the triangle order changes; falls
        back to greedy if the bundled library is not reachable, and with ``join=None``)

    Returns
    -------
    (n,) int64
        strip indices (or a list of strips for ``join=None``).
    """
    if join not in JOINS:
        raise ConfigError(f"strip join must be one of {JOINS}, got {join!r}")
    if method not in METHODS:
        raise ConfigError(f"stripify method must be one of {METHODS}, got {method!r}")
    tris = _nondegenerate(_as_triangles(triangles))
    if method == "meshopt" and join is not None and tris.size:
        s = _meshopt_strip(tris, join == "restart")
        if s is not None:
            return s
    strips = _greedy_strips(tris)
    if join is None:
        return strips
    return _join(strips, join)


def unstripify(strip: npt.ArrayLike | Sequence[npt.ArrayLike]) -> np.ndarray:
    """Triangles ``(t, 3) int64`` of a strip (``RESTART`` markers split it; parity restarts after
    each; triangles with a repeated index are dropped). Accepts a list of strips too."""
    if isinstance(strip, (list, tuple)) and strip and not np.isscalar(strip[0]):
        return np.concatenate([unstripify(s) for s in strip]) if strip else np.zeros((0, 3), np.int64)
    s = np.asarray(strip, dtype=np.int64).reshape(-1)
    if s.size < 3:
        return np.zeros((0, 3), np.int64)
    # position of each index within its strip (reset after every restart marker)
    is_r = s == RESTART
    seg_start = np.maximum.accumulate(np.where(is_r, np.arange(s.size) + 1, 0))
    local = np.arange(s.size) - seg_start
    i = np.arange(s.size - 2)
    a, b, c = s[i], s[i + 1], s[i + 2]
    valid = (~is_r[i]) & (~is_r[i + 1]) & (~is_r[i + 2]) & (local[i + 2] >= 2)
    odd = (local[i] % 2) == 1
    tri = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], -1)
    tri = tri[valid]
    return _nondegenerate(tri)


def canonical_triangles(triangles: np.ndarray) -> np.ndarray:
    """Triangles rotated so the smallest index comes first (winding kept), sorted: two lists
    describe the same oriented triangles iff their canonical forms are equal."""
    t = _nondegenerate(_as_triangles(triangles))
    if not t.size:
        return t
    r = np.argmin(t, axis=1)
    idx = (r[:, None] + np.arange(3)[None, :]) % 3
    t = np.take_along_axis(t, idx, axis=1)
    return t[np.lexsort(t.T[::-1])]


def strip_stats(triangles: np.ndarray, strip: npt.ArrayLike | Sequence[npt.ArrayLike]) -> dict[str, Any]:
    """Figures for one strip sequence of ``triangles``.

    Returns a dict with ``triangles``, ``strips`` (runs between restart markers; 1 for a
    degenerate-joined sequence), ``indices`` (length of the sequence incl. markers/repeats),
    ``nonindexed_vertices`` (vertices sent when each strip position carries its full vertex:
    restart markers cost nothing, PS2 ADC style; repeated indices are sent),
    ``indexed_unique_vertices``, ``vertices_per_triangle`` (non-indexed),
    ``indices_per_triangle`` and ``list_vertices_per_triangle`` (= 3, an unstripped list).
    """
    tris = _nondegenerate(_as_triangles(triangles))
    s = np.asarray(strip, dtype=np.int64).reshape(-1)
    nt = max(tris.shape[0], 1)
    markers = int(np.sum(s == RESTART))
    sent = s.size - markers
    uniq = int(np.unique(s[s != RESTART]).size)
    return {
        "triangles": int(tris.shape[0]),
        "strips": markers + 1 if s.size else 0,
        "indices": int(s.size),
        "nonindexed_vertices": int(sent),
        "indexed_unique_vertices": uniq,
        "vertices_per_triangle": sent / nt,
        "indices_per_triangle": s.size / nt,
        "list_vertices_per_triangle": 3.0,
    }
