"""Hierarchical frustum culling of patches: a bounding-volume tree over the patch boxes.

Patches are sorted along a Morton (Z-order) curve of their box centres in x-y, grouped into
leaves of ``leaf`` consecutive patches, and the leaves into an implicit complete binary tree
(bounds per level, computed bottom-up).  A frustum walks the tree one level at a time (numpy over
the level's live nodes): a node wholly outside one plane is dropped with everything below it, a
node wholly inside every plane is taken whole (its patch range, no further tests), the rest
descend; at the leaves the straddling leaves' patches are tested one by one.  The cost grows with
the visible boundary, not with the net: a 160k-patch net culls in about the time of a 2,560-patch
one once the view's far plane caps the visible set.

The result is exactly :func:`piste.transforms.cull_boxes` on every patch (a node inside every
plane has every box below it inside; a node outside one plane has every box below it outside),
so swapping the flat test for the tree never changes a picture.

API
---
PatchTree(lo, hi, leaf=16)      build from per-patch bounds ``(n, 3)`` (``net.patch_bounds``)
PatchTree.cull(planes)          ``(p,)`` int64 visible patch ids, ascending
patch_tree(net)                 the tree of a net, built once and kept on the net
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from piste.errors import ValidationError
from piste.terrain import _kernels
from piste.terrain.lod import kept_patch_bounds

if TYPE_CHECKING:
    from piste.terrain.net import PatchNet

__all__ = ["PatchTree", "patch_tree"]


def _part1by1(x: np.ndarray) -> np.ndarray:
    """Spread the low 16 bits of ``x`` to the even bits (Morton interleave)."""
    x = x.astype(np.uint32) & 0x0000FFFF
    x = (x | (x << 8)) & 0x00FF00FF
    x = (x | (x << 4)) & 0x0F0F0F0F
    x = (x | (x << 2)) & 0x33333333
    x = (x | (x << 1)) & 0x55555555
    return x


def _classify(lo: np.ndarray, hi: np.ndarray, planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(outside, inside)`` booleans ``(k,)`` of boxes ``lo, hi (k, 3)`` against inward planes ``(6, 4)``."""
    centre = (lo + hi) * 0.5
    half = (hi - lo) * 0.5
    dist = centre @ planes[:, :3].T + planes[:, 3]  # (k, 6)
    reach = half @ np.abs(planes[:, :3]).T
    outside = (dist + reach < 0.0).any(axis=1)
    inside = (dist - reach >= 0.0).all(axis=1)
    return outside, inside


class PatchTree:
    """A bounding-volume tree over ``n`` axis-aligned boxes (see the module docstring).

    Parameters
    ----------
    lo, hi : (n, 3) float64 box corners (per-patch control-point bounds)
    leaf : patches per leaf
    """

    def __init__(self, lo: npt.ArrayLike, hi: npt.ArrayLike, leaf: int = 16) -> None:
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        if lo.ndim != 2 or lo.shape[1] != 3 or lo.shape != hi.shape or len(lo) == 0:
            raise ValidationError(f"patch bounds must be two (n, 3) arrays with n >= 1, got {lo.shape} and {hi.shape}")
        if leaf < 1:
            raise ValidationError(f"leaf size must be >= 1, got {leaf}")
        n = len(lo)
        self.n = n
        self.leaf = int(leaf)
        c = (lo + hi) * 0.5
        cmin, cmax = c[:, :2].min(0), c[:, :2].max(0)
        q = ((c[:, :2] - cmin) / np.maximum(cmax - cmin, 1e-300) * 65535.0).astype(np.int64)
        code = _part1by1(q[:, 0]) | (_part1by1(q[:, 1]) << 1)
        self.order = np.argsort(code, kind="stable").astype(np.int64)  # sorted position -> patch id
        self.lo_sorted = np.ascontiguousarray(lo[self.order])
        self.hi_sorted = np.ascontiguousarray(hi[self.order])
        n_leaves = -(-n // self.leaf)
        depth = max(int(np.ceil(np.log2(n_leaves))), 0) if n_leaves > 1 else 0
        width = 1 << depth
        starts = np.minimum(np.arange(width, dtype=np.int64) * self.leaf, n)
        ends = np.minimum(starts + self.leaf, n)
        # leaf bounds (empty padding leaves copy the last real leaf's box: they hold no patches)
        real = starts < n
        llo = np.minimum.reduceat(self.lo_sorted, starts[real], axis=0)
        lhi = np.maximum.reduceat(self.hi_sorted, starts[real], axis=0)
        pad = width - len(llo)
        llo = np.concatenate([llo, np.repeat(llo[-1:], pad, axis=0)])
        lhi = np.concatenate([lhi, np.repeat(lhi[-1:], pad, axis=0)])
        self.levels_lo, self.levels_hi = [llo], [lhi]
        while len(self.levels_lo[-1]) > 1:
            a, b = self.levels_lo[-1], self.levels_hi[-1]
            self.levels_lo.append(np.minimum(a[0::2], a[1::2]))
            self.levels_hi.append(np.maximum(b[0::2], b[1::2]))
        self.levels_lo.reverse()  # root first
        self.levels_hi.reverse()
        self.leaf_start, self.leaf_end = starts, ends
        self.node_lo = np.ascontiguousarray(np.concatenate(self.levels_lo))  # heap order: root, then level 1, ...
        self.node_hi = np.ascontiguousarray(np.concatenate(self.levels_hi))

    @property
    def depth(self) -> int:
        return len(self.levels_lo) - 1

    def cull(self, planes: npt.ArrayLike, use_numba: bool | None = None) -> np.ndarray:
        """Patch ids whose boxes are not wholly outside one of ``planes (6, 4)`` (inward), ``(p,)``
        int64 ascending: the same set as :func:`piste.transforms.cull_boxes` over every box.
        Compiled depth-first walk with numba, else a level-by-level numpy walk (same result)."""
        planes = np.asarray(planes, dtype=np.float64)
        if _kernels.cull_ready() if use_numba is None else use_numba:
            pos = _kernels.cull_tree(self.node_lo, self.node_hi, self.leaf_start, self.leaf_end, self.lo_sorted,
                                     self.hi_sorted, self.depth, planes)
            return np.sort(self.order[pos])
        live = np.zeros(1, dtype=np.int64)
        taken_nodes = []  # (level, node ids) wholly inside
        depth = self.depth
        for lvl in range(depth + 1):
            if not len(live):
                break
            outside, inside = _classify(self.levels_lo[lvl][live], self.levels_hi[lvl][live], planes)
            if inside.any():
                taken_nodes.append((lvl, live[inside]))
            live = live[~outside & ~inside]
            if lvl < depth:
                live = (live[:, None] * 2 + np.arange(2)).ravel()
        ranges_s, ranges_e = [], []
        for lvl, nodes in taken_nodes:
            span = 1 << (depth - lvl)  # leaves under one node at this level
            first_leaf = nodes * span
            s = self.leaf_start[first_leaf]
            e = self.leaf_end[np.minimum(first_leaf + span - 1, len(self.leaf_end) - 1)]
            ranges_s.append(s)
            ranges_e.append(e)
        parts = []
        if ranges_s:
            s = np.concatenate(ranges_s)
            e = np.concatenate(ranges_e)
            parts.append(_ranges(s, e - s))
        if len(live):  # straddling leaves: test their patches one by one
            s, e = self.leaf_start[live], self.leaf_end[live]
            cand = _ranges(s, e - s)
            outside, _ = _classify(self.lo_sorted[cand], self.hi_sorted[cand], planes)
            parts.append(cand[~outside])
        if not parts:
            return np.zeros(0, dtype=np.int64)
        pos = np.concatenate(parts)
        return np.sort(self.order[pos])


def _ranges(starts: np.ndarray, counts: npt.ArrayLike) -> np.ndarray:
    counts = np.asarray(counts, dtype=np.int64)
    keep = counts > 0
    starts, counts = starts[keep], counts[keep]
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    off = np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(starts, counts) + np.arange(total) - off


def patch_tree(net: PatchNet, leaf: int = 16) -> PatchTree:
    """The :class:`PatchTree` of ``net``'s patch bounds, built on first use and kept on the net."""
    t = net.__dict__.get("_patch_tree")
    if t is None or t.leaf != leaf:
        lo, hi = kept_patch_bounds(net)
        t = PatchTree(lo, hi, leaf)
        net.__dict__["_patch_tree"] = t
    return t
