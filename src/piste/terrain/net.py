"""PatchNet: a curve net of bicubic Bézier patches with computed topology.

Conventions
-----------
Control points ``P[i, j]``: ``i`` runs along ``u``, ``j`` along ``v``.  Corners and sides::

    c3 (0,1) ---- side 2 (v=1) ---> c2 (1,1)
      ^                              ^
    side 3 (u=0)                  side 1 (u=1)
      |                              |
    c0 (0,0) ---- side 0 (v=0) ---> c1 (1,0)

Each side runs in the direction of increasing parameter (arrows).  Sides are welded into edges:
a side's four control points are welded to point ids (within ``tol``); an edge is the set of sides
with the same ids in either direction.  ``side_flip`` says whether a side runs against its edge's
canonical direction.  Welding snaps coincident boundary control points to one value, so shared
edges are exactly equal in both patches (the basis of bit-identical, crack-free tessellation).
"""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.errors import FormatError, ValidationError
from piste.formats.atomic import atomic_path
from piste.graph import connected_parts
# the .bpt reader and the height-field fit through the packages' lazy names (PEP 562): used by
# PatchNet.from_bpt / from_heightfield only, so a bundle load imports neither
from piste import formats as _formats, terrain as _terrain
from piste.formats.safe_io import open_file
from piste.terrain.bezier import evaluate
from piste.terrain.lod import edge_levels

log = logging.getLogger(__name__)

#: control-point indices (i, j) of each side, in the side's own direction: (4 sides, 4 points, 2)
SIDE_INDEX = np.array(
    [
        [(0, 0), (1, 0), (2, 0), (3, 0)],  # side 0: v = 0, u increasing
        [(3, 0), (3, 1), (3, 2), (3, 3)],  # side 1: u = 1, v increasing
        [(0, 3), (1, 3), (2, 3), (3, 3)],  # side 2: v = 1, u increasing
        [(0, 0), (0, 1), (0, 2), (0, 3)],  # side 3: u = 0, v increasing
    ]
)
#: control-point indices (i, j) of the four corners c0..c3
CORNER_INDEX = np.array([(0, 0), (3, 0), (3, 3), (0, 3)])
#: the corners at the start and end of each side
SIDE_CORNERS = np.array([(0, 1), (1, 2), (3, 2), (0, 3)])
SIDE_NAMES = ("v=0", "u=1", "v=1", "u=0")
#: relative gap (of the edge chord) under which two sides with welded end points are taken as one
#: shared edge that fails C0, rather than two distinct open edges
C0_NEAR_MISS = 0.05
#: the stored form of a net's topology (:meth:`PatchNet.topology`): array name -> (dtype, shape)
TOPOLOGY_ARRAYS = {"side_edge": ("int32", ("n", 4)), "side_flip": ("bool", ("n", 4)),
                   "edge_patches": ("int32", ("e", 2)), "edge_sides": ("int32", ("e", 2)),
                   "edge_degenerate": ("bool", ("e",)), "corner_ids": ("int32", ("n", 4))}
#: version of that form (a bundle's ``terrain.topology``; another value is recomputed on load)
TOPOLOGY_FORMAT = 1
#: the topology :meth:`PatchNet.from_topology` hands to ``__post_init__`` (per thread)
_STORED_TOPOLOGY = threading.local()
_BOUNDARY = np.zeros((4, 4), dtype=bool)
_BOUNDARY[[0, 3], :] = True
_BOUNDARY[:, [0, 3]] = True


def _side_str(patch: int, side: int) -> str:
    return f"patch {patch} edge {side} ({SIDE_NAMES[side]})"


def weld_points(points: np.ndarray, tol: float) -> np.ndarray:
    """Cluster points closer than ``tol`` (transitively); returns ``(m,)`` int ids, numbered by
    first occurrence, so the result is deterministic.

    numpy only (no scipy on the runtime path: importing it cost a fresh process 0.5 s before its
    first frame): exact duplicates first, then candidate pairs of the distinct points along a
    generic direction (a sliding window over the sorted projections: points within ``tol`` in 3-D
    are within ``tol`` along any direction), checked in 3-D, joined by
    :func:`piste.graph.connected_parts`.  Dense
    clusters (a window over 64 points wide) fall back to scipy's k-d tree.  The same clusters as
    ``cKDTree.query_pairs(tol)`` + connected components.

    Parameters
    ----------
    points : (m, 3) float64
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    m = len(pts)
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    uniq, inv = np.unique(pts, axis=0, return_inverse=True)
    inv = inv.ravel()
    u = len(uniq)
    labels = np.arange(u, dtype=np.int64)
    if tol > 0 and u > 1:
        direction = np.array([0.5773502691896258, 0.5773502691896257, 0.5773502691896259]) + [1e-3, -2e-3, 0.0]
        proj = uniq @ direction
        order = np.argsort(proj, kind="stable")
        sp = proj[order]
        a_list, b_list = [], []
        k = 1
        while k < u:
            close = (sp[k:] - sp[:-k]) <= tol * 1.01  # the projection is within tol (a margin for rounding)
            if not close.any():
                break
            if k > 64:
                return _weld_scipy(pts, tol)
            i = np.flatnonzero(close)
            a, b = order[i], order[i + k]
            d = uniq[a] - uniq[b]
            near = np.einsum("ij,ij->i", d, d) <= tol * tol
            a_list.append(a[near])
            b_list.append(b[near])
            k += 1
        if a_list:
            _, labels = connected_parts(u, np.stack([np.concatenate(a_list), np.concatenate(b_list)], axis=1))
    comp = labels[inv]
    _, first = np.unique(comp, return_index=True)
    order = np.argsort(first)
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    _, dense = np.unique(comp, return_inverse=True)
    return rank[dense.ravel()]


def _weld_scipy(points: np.ndarray, tol: float) -> np.ndarray:
    """:func:`weld_points` by scipy's k-d tree (dense clusters; the reference the tests compare with)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    m = len(points)
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray") if m else np.zeros((0, 2), int)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, labels = connected_components(graph, directed=False)
    # renumber by first occurrence
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[labels]


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class PatchNet(DataMethods):
    """A net of ``n`` bicubic Bézier patches.

    Attributes
    ----------
    control_points : (n, 4, 4, 3) float64, welded (shared boundary points exactly equal)
    uv : (n, 4, 2) float32, base-texture UV at the corners c0..c3
    lightmap_rect : (n, 4) float32, ``(u0, v0, u1, v1)`` of each patch's light-map tile in the atlas
        (texel-centre mapping: parameter (0, 0) maps to (u0, v0), (1, 1) to (u1, v1))
    tol : welding tolerance in model units
    name : a label for messages

    Topology (computed in ``__post_init__``)
    ----------------------------------------
    side_edge : (n, 4) int32, edge id of each side
    side_flip : (n, 4) bool, side runs against its edge's canonical direction
    edge_cp : (e, 4, 3) float64, canonical edge control points
    edge_patches, edge_sides : (e, 2) int32, the (up to two) patch sides on each edge, -1 if none
    edge_degenerate : (e,) bool, a collapsed edge (all four control points welded together)
    corner_ids : (n, 4) int32, welded point id of each corner
    """

    control_points: np.ndarray
    # None (the constructor's default) is replaced in __post_init__: typed as what every net holds
    uv: np.ndarray = None  # type: ignore[assignment]
    lightmap_rect: np.ndarray = None  # type: ignore[assignment]
    tol: float = None  # type: ignore[assignment]
    name: str = "net"
    side_edge: np.ndarray = field(init=False, repr=False)
    side_flip: np.ndarray = field(init=False, repr=False)
    edge_cp: np.ndarray = field(init=False, repr=False)
    edge_patches: np.ndarray = field(init=False, repr=False)
    edge_sides: np.ndarray = field(init=False, repr=False)
    edge_degenerate: np.ndarray = field(init=False, repr=False)
    corner_ids: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cp = np.array(self.control_points, dtype=np.float64)
        if cp.ndim != 4 or cp.shape[1:] != (4, 4, 3):
            raise ValidationError(f"{self.name}: control_points must have shape (n, 4, 4, 3), got {cp.shape}")
        if len(cp) == 0:
            raise ValidationError(f"{self.name}: a patch net needs at least one patch")
        if not np.isfinite(cp).all():  # (the point named only when one is bad: the per-point test is slower)
            bad = ~np.isfinite(cp).all(axis=-1)
            p, i, j = (int(x) for x in np.argwhere(bad)[0])
            sides = [s for s in range(4) if any((i, j) == tuple(ij) for ij in SIDE_INDEX[s])]
            where = f"edge {sides[0]} ({SIDE_NAMES[sides[0]]}), " if sides else "interior, "
            raise ValidationError(
                f"{self.name}: patch {p} {where}control point [{i}][{j}] is {cp[p, i, j].tolist()}: "
                "expected finite coordinates"
            )
        n = len(cp)
        if self.tol is None:
            diag = float(np.linalg.norm(_extent(cp, np.maximum) - _extent(cp, np.minimum)))
            self.tol = max(diag, 1.0) * 1e-6
        self.tol = float(self.tol)
        if self.uv is None:
            self.uv = np.broadcast_to(np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32), (n, 4, 2)).copy()
        self.uv = np.asarray(self.uv, dtype=np.float32).reshape(n, 4, 2)
        if self.lightmap_rect is None:
            self.lightmap_rect = default_lightmap_rects(n, 8)
        self.lightmap_rect = np.asarray(self.lightmap_rect, dtype=np.float32).reshape(n, 4)
        self.control_points = cp
        stored = getattr(_STORED_TOPOLOGY, "value", None)
        if stored is not None:  # PatchNet.from_topology: checked, not recomputed
            self._set_topology(stored)
        else:
            self._build_topology()

    # ------------------------------------------------------------------ topology
    def topology(self) -> dict[str, np.ndarray]:
        """The computed topology as arrays (what a bundle stores so a load need not weld again):
        ``side_edge (n, 4) int32, side_flip (n, 4) bool, edge_patches (e, 2) int32, edge_sides (e, 2)
        int32, edge_degenerate (e,) bool, corner_ids (n, 4) int32`` (``edge_cp`` follows from them).
        :meth:`from_topology` reads them back; format :data:`TOPOLOGY_FORMAT`."""
        return {k: getattr(self, k) for k in TOPOLOGY_ARRAYS}

    @classmethod
    def from_topology(cls, control_points: np.ndarray, topology: dict, uv: np.ndarray | None = None,
                      lightmap_rect: np.ndarray | None = None, tol: float | None = None,
                      name: str = "net") -> "PatchNet":
        """A net whose topology is given (:meth:`topology` of the same, already welded, control
        points) instead of computed: the welding and edge matching (~0.1 s at 2.5k patches) are
        skipped, the arrays are checked instead (shapes, dtypes, index ranges, every side on exactly
        one edge, the two sides of every shared edge bit-identical, welded corners equal).  Raises
        :class:`~piste.errors.ValidationError` naming the array when they do not describe these
        control points; the result is the same net as ``PatchNet(control_points, ...)``."""
        _STORED_TOPOLOGY.value = topology
        try:
            return cls(control_points, uv=uv, lightmap_rect=lightmap_rect, tol=tol, name=name)  # type: ignore[arg-type]
        finally:
            _STORED_TOPOLOGY.value = None

    def _set_topology(self, topo: dict) -> None:
        """Take a stored topology after checking it against the control points (vectorised)."""
        cp = self.control_points
        n = len(cp)

        def bad(key: str, why: str) -> ValidationError:
            return ValidationError(f"{self.name}: stored topology {key}: {why}")

        if not isinstance(topo, dict):
            raise bad("", f"expected a dict of arrays, got {type(topo).__name__}")
        a = {}
        for key, (dtype, shape) in TOPOLOGY_ARRAYS.items():
            if key not in topo:
                raise bad(key, "missing")
            v = np.asarray(topo[key])
            if v.dtype != np.dtype(dtype) or v.ndim != len(shape):
                raise bad(key, f"expected {dtype} of {len(shape)} dimensions, got {v.dtype} {v.shape}")
            a[key] = v
        e = len(a["edge_patches"])
        want = {"side_edge": (n, 4), "side_flip": (n, 4), "corner_ids": (n, 4), "edge_patches": (e, 2),
                "edge_sides": (e, 2), "edge_degenerate": (e,)}
        for key, shape in want.items():
            if a[key].shape != shape:
                raise bad(key, f"expected shape {shape}, got {a[key].shape}")
        ep, es, se = a["edge_patches"].astype(np.int64), a["edge_sides"].astype(np.int64), a["side_edge"]
        used = ep >= 0
        if e == 0 or not used[:, 0].all() or (ep >= n).any() or (ep < -1).any():
            raise bad("edge_patches", f"expected patch ids in [0, {n}) (the second may be -1)")
        if ((es < 0) != ~used).any() or (es > 3).any():
            raise bad("edge_sides", "expected sides 0..3 where edge_patches has a patch, -1 elsewhere")
        if (se < 0).any() or (se >= e).any():
            raise bad("side_edge", f"expected edge ids in [0, {e})")
        slots = (ep * 4 + es)[used]  # every (patch, side) exactly once
        if len(slots) != 4 * n or (np.bincount(slots, minlength=4 * n) != 1).any():
            raise bad("edge_patches", "every patch side must lie on exactly one edge")
        if (se.ravel()[slots] != np.broadcast_to(np.arange(e)[:, None], (e, 2))[used]).any():
            raise bad("side_edge", "does not match edge_patches / edge_sides")
        cid = a["corner_ids"].astype(np.int64)
        if (cid < 0).any() or (cid >= 12 * n).any():
            raise bad("corner_ids", f"expected point ids in [0, {12 * n})")
        flip = a["side_flip"]
        ends = cid[:, SIDE_CORNERS]  # (n, 4, 2) ids at each side's start and end
        open_side = ends[..., 0] != ends[..., 1]  # the canonical direction runs from the lower id
        if (flip[open_side] != (ends[..., 0] > ends[..., 1])[open_side]).any():
            raise bad("side_flip", "does not run each edge from its lower to its higher corner id")
        # (4n, 4, 3) in each side's direction: the rows / columns of SIDE_INDEX as slices (a fancy-index
        # gather of the same points cost ~2.5 ms at 2.5k patches)
        pts = np.stack([cp[:, :, 0], cp[:, 3, :], cp[:, :, 3], cp[:, 0, :]], axis=1).reshape(n * 4, 4, 3)
        flat_flip = flip.reshape(-1)

        def canonical(sides: np.ndarray) -> np.ndarray:  # the sides' points in their edges' direction, (k, 4, 3)
            out = pts[sides]
            f = flat_flip[sides]
            out[f] = out[f, ::-1]
            return out

        first = canonical(ep[:, 0] * 4 + es[:, 0])  # (e, 4, 3)
        two = used[:, 1]
        if (canonical(ep[two, 1] * 4 + es[two, 1]) != first[two]).any():
            raise bad("edge_patches", "the two sides of a shared edge differ (not the welded control points)")
        deg = a["edge_degenerate"]
        d = np.flatnonzero(deg)  # (only the flagged edges' points compared: ~0.3 ms less at 5k edges)
        if (deg & two).any() or not (first[d] == first[d, :1]).all():
            raise bad("edge_degenerate", "a degenerate edge must have one side and four equal points")
        cid = cid.ravel()
        corners = cp[:, CORNER_INDEX[:, 0], CORNER_INDEX[:, 1]].reshape(-1, 3)
        rep = np.full(int(cid.max()) + 1, -1, dtype=np.int64)
        rep[cid[::-1]] = np.arange(len(cid))[::-1]  # the first corner of each id
        if (corners != corners[rep[cid]]).any():
            raise bad("corner_ids", "corners with one id are not the same point")
        self.side_edge, self.side_flip, self.corner_ids = se, flip, a["corner_ids"]
        self.edge_patches, self.edge_sides, self.edge_degenerate = a["edge_patches"], a["edge_sides"], deg
        self.edge_cp = np.ascontiguousarray(first)

    def _build_topology(self) -> None:
        cp = self.control_points
        n = len(cp)
        bpts = cp[:, _BOUNDARY]  # (n, 12, 3)
        ids = weld_points(bpts.reshape(-1, 3), self.tol)
        # snap every welded point to its cluster's first member
        flat = bpts.reshape(-1, 3)
        first = np.full(ids.max() + 1, -1)
        first[ids[::-1]] = np.arange(len(ids))[::-1]
        cp[:, _BOUNDARY] = flat[first[ids]].reshape(n, 12, 3)
        pid = np.full((n, 4, 4), -1, dtype=np.int64)
        pid[:, _BOUNDARY] = ids.reshape(n, 12)
        self.corner_ids = pid[:, CORNER_INDEX[:, 0], CORNER_INDEX[:, 1]].astype(np.int32)

        keys = pid[:, SIDE_INDEX[..., 0], SIDE_INDEX[..., 1]].reshape(n * 4, 4)  # (n*4, 4)
        flip = (keys[:, 0] > keys[:, 3]) | ((keys[:, 0] == keys[:, 3]) & (keys[:, 1] > keys[:, 2]))
        canon = np.where(flip[:, None], keys[:, ::-1], keys)
        degenerate = (canon == canon[:, :1]).all(axis=1)
        # degenerate sides never pair: give each a unique key
        canon = canon.copy()
        side_no = np.arange(n * 4)
        canon[degenerate] = np.stack([-1 - side_no[degenerate]] * 4, axis=1)
        uniq, inverse, counts = np.unique(canon, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        over = np.nonzero(counts > 2)[0]
        if len(over):
            sides = np.nonzero(inverse == over[0])[0]
            names = ", ".join(_side_str(int(s) // 4, int(s) % 4) for s in sides)
            raise ValidationError(f"{self.name}: an edge is shared by more than two patches: {names}")
        self._check_c0(canon, degenerate, keys)

        e = len(uniq)
        edge_patches = np.full((e, 2), -1, dtype=np.int32)
        edge_sides = np.full((e, 2), -1, dtype=np.int32)
        order = np.argsort(inverse, kind="stable")
        sorted_e = inverse[order]
        slot = np.zeros(n * 4, dtype=np.int64)
        starts = np.searchsorted(sorted_e, sorted_e, side="left")
        slot[order] = np.arange(n * 4) - starts
        edge_patches[inverse, slot] = side_no // 4
        edge_sides[inverse, slot] = side_no % 4
        # canonical control points: from the first side, reversed if that side is flipped
        p0, s0 = edge_patches[:, 0], edge_sides[:, 0]
        ecp = cp[p0[:, None], SIDE_INDEX[s0][..., 0], SIDE_INDEX[s0][..., 1]]  # (e, 4, 3)
        f0 = flip[p0 * 4 + s0]
        ecp[f0] = ecp[f0, ::-1]
        self.side_edge = inverse.reshape(n, 4).astype(np.int32)
        self.side_flip = flip.reshape(n, 4)
        self.edge_cp = ecp
        self.edge_patches = edge_patches
        self.edge_sides = edge_sides
        self.edge_degenerate = degenerate[order][np.searchsorted(sorted_e, np.arange(e))]

    def _check_c0(self, canon: np.ndarray, degenerate: np.ndarray, keys: np.ndarray) -> None:
        """Sides that share both end points and nearly, but not within ``tol``, their middle
        control points are a shared edge that breaks C0.

        "Nearly" is a gap of at most ``C0_NEAR_MISS`` of the edge's chord: two open sides that merely
        meet at their ends (the teapot's handle halves) differ by far more and stay boundaries.
        """
        ok = ~degenerate & (canon[:, 0] != canon[:, 3])
        idx = np.nonzero(ok)[0]
        if len(idx) < 2:
            return
        ends = np.sort(canon[idx][:, [0, 3]], axis=1)
        order = np.lexsort((ends[:, 1], ends[:, 0]))
        same = (ends[order][1:] == ends[order][:-1]).all(axis=1)
        a_all, b_all = idx[order][:-1][same], idx[order][1:][same]
        differ = (canon[a_all] != canon[b_all]).any(axis=1)
        for a, b in zip(a_all[differ], b_all[differ]):
            pa = self._side_points(a // 4, a % 4, keys[a][0] > keys[a][3])
            pb = self._side_points(b // 4, b % 4, keys[b][0] > keys[b][3])
            gap = float(np.abs(pa - pb).max())
            chord = float(np.linalg.norm(pa[3] - pa[0]))
            if gap <= C0_NEAR_MISS * chord:
                raise ValidationError(
                    f"{self.name}: {_side_str(a // 4, a % 4)} and {_side_str(b // 4, b % 4)} share their end points "
                    f"but their middle control points differ by {gap:.6g} (tolerance {self.tol:.3g}): "
                    "C0 continuity violated"
                )

    def _side_points(self, p: int, s: int, flipped: bool) -> np.ndarray:
        pts = self.control_points[p, SIDE_INDEX[s][:, 0], SIDE_INDEX[s][:, 1]]
        return pts[::-1] if flipped else pts

    # ------------------------------------------------------------------ properties
    @property
    def n_patches(self) -> int:
        return len(self.control_points)

    def __len__(self) -> int:
        return len(self.control_points)

    @property
    def n_edges(self) -> int:
        return len(self.edge_cp)

    @property
    def boundary_edges(self) -> np.ndarray:
        """Ids of non-degenerate edges with a single patch (the net's true boundary), ``(b,)``."""
        return np.nonzero((self.edge_patches[:, 1] < 0) & ~self.edge_degenerate)[0]

    @property
    def shared_edges(self) -> np.ndarray:
        """Ids of edges shared by two patches, ``(s,)``."""
        return np.nonzero(self.edge_patches[:, 1] >= 0)[0]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds of all control points (which contain the surface): ``(min (3,), max (3,))``
        float64.  Reduced over rows of 48 contiguous values (one patch) and then the 16 points: ~20x
        faster than ``reshape(-1, 3).min(0)`` (numpy's strided 3-wide reduction), computed at each call
        (no cache to go stale when the control points are edited in place)."""
        return _extent(self.control_points, np.minimum), _extent(self.control_points, np.maximum)

    @property
    def patch_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-patch control-point bounds (convex-hull property): ``(min (n, 3), max (n, 3))`` float64.
        Halving the 16 points of every patch four times (elementwise, contiguous): ~10x faster than
        ``reshape(n, 16, 3).min(1)``; the same values.  Computed at each call (see :attr:`bounds`)."""
        return _fold(self.control_points, np.minimum), _fold(self.control_points, np.maximum)

    @property
    def patch_size(self) -> np.ndarray:
        """A size per patch: the longest corner-to-corner diagonal, ``(n,)`` float64."""
        c = self.control_points[:, CORNER_INDEX[:, 0], CORNER_INDEX[:, 1]]
        return np.maximum(np.linalg.norm(c[:, 2] - c[:, 0], axis=-1), np.linalg.norm(c[:, 3] - c[:, 1], axis=-1))

    def edge_midpoints(self) -> np.ndarray:
        """Point of every edge curve at t = 0.5, ``(e, 3)`` float64."""
        c = self.edge_cp
        return (c[:, 0] + 3.0 * c[:, 1] + 3.0 * c[:, 2] + c[:, 3]) / 8.0

    # ------------------------------------------------------------------ evaluation, LOD
    def evaluate(self, u: npt.ArrayLike, v: npt.ArrayLike, normals: bool = True) -> Any:
        """Positions (and normals) of every patch at parameters ``(u[s], v[s])``: ``(n, s, 3)`` float64."""
        return evaluate(self.control_points, u, v, normals=normals)

    def edge_levels(self, eye: npt.ArrayLike, **kwargs: Any) -> np.ndarray:
        """Vertices per edge (4, 6 or 8) for a camera at ``eye``: ``(e,)`` int8.  See :func:`piste.terrain.lod.edge_levels`."""
        return edge_levels(self, eye, **kwargs)

    # ------------------------------------------------------------------ I/O
    @classmethod
    def from_bpt(cls, path: str | os.PathLike[str], **kwargs: Any) -> "PatchNet":
        """Read Newell's patch text format (see :mod:`piste.formats.bpt`)."""
        return cls(_formats.read_bpt(path), name=Path(path).name, **kwargs)

    @classmethod
    def from_control_grid(cls, grid: npt.ArrayLike, **kwargs: Any) -> "PatchNet":
        """A rectangular net from a shared control-point grid.

        Parameters
        ----------
        grid : (3R + 1, 3C + 1, 3) control points; patch (r, c) takes ``grid[3r:3r+4, 3c:3c+4]``
            with ``i`` (u) along the second axis and ``j`` (v) along the first, so for a grid laid
            out in x (columns) and y (rows) the patches face +z.

        Returns
        -------
        PatchNet of ``R * C`` patches (row-major), C0 by construction.
        """
        g = np.asarray(grid, dtype=np.float64)
        if g.ndim != 3 or g.shape[2] != 3 or (g.shape[0] - 1) % 3 or (g.shape[1] - 1) % 3 or min(g.shape[:2]) < 4:
            raise ValidationError(f"control grid must have shape (3R+1, 3C+1, 3), got {g.shape}")
        rows, cols = (g.shape[0] - 1) // 3, (g.shape[1] - 1) // 3
        r = 3 * np.arange(rows)[:, None, None, None] + np.arange(4)[None, None, None, :]  # j -> grid row
        c = 3 * np.arange(cols)[None, :, None, None] + np.arange(4)[None, None, :, None]  # i -> grid col
        cp = g[r, c]  # (R, C, 4 i, 4 j, 3)
        return cls(cp.reshape(rows * cols, 4, 4, 3), **kwargs)

    @classmethod
    def from_heightfield(cls, z: npt.ArrayLike, spacing: float | tuple[float, float], **kwargs: Any) -> "PatchNet":
        """Fit a C0 net to a height field by least squares (see :func:`piste.terrain.fit.fit_heightfield`;
        the solve is :func:`piste.terrain.heightfield.fit_control_points`)."""
        name = kwargs.pop("name", "heightfield")
        grid = _terrain.fit_control_points(z, spacing, **kwargs)
        net = cls(grid.control_points, uv=grid.uv, tol=grid.tol, name=name)
        net.grid_shape = grid.grid_shape  # type: ignore[attr-defined]  # only a fitted net has one; patches per column and per row: patch py * Px + px
        log.log(logging.INFO if kwargs.get("progress") else logging.DEBUG, "fit_heightfield: PatchNet of %d patches",
                len(net))
        return net

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the net losslessly to ``path`` (``.npz``), atomically."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(
                    fh,
                    format=np.array("piste.PatchNet/1"),
                    control_points=self.control_points,
                    uv=self.uv,
                    lightmap_rect=self.lightmap_rect,
                    tol=np.float64(self.tol),
                    name=np.array(self.name),
                )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "PatchNet":
        """Read a net written by :meth:`save`."""
        path = Path(path)
        try:  # regular files only, no links below a confinement root (piste.formats.safe_io)
            fh = open_file(path, what="patch net")
        except FormatError as exc:
            if "No such file" in getattr(exc, "reason", ""):
                raise FormatError(path, "no such file") from None
            raise
        try:
            data = np.load(fh, allow_pickle=False)
        except Exception as exc:  # zipfile/pickle errors: not an npz
            fh.close()
            raise FormatError(path, f"not a piste .npz patch net ({exc})") from None
        if not hasattr(data, "files"):
            fh.close()
            raise FormatError(path, "not a piste .npz patch net (a single .npy array)")
        with fh, data:
            for key in ("control_points", "uv", "lightmap_rect", "tol"):
                if key not in data.files:
                    raise FormatError(path, "missing array", field=key)
            fmt = str(data["format"]) if "format" in data.files else "?"
            if fmt != "piste.PatchNet/1":
                raise FormatError(path, f"expected format 'piste.PatchNet/1', got {fmt!r}", field="format")
            try:
                return cls(
                    data["control_points"],
                    uv=data["uv"],
                    lightmap_rect=data["lightmap_rect"],
                    tol=float(data["tol"]),
                    name=str(data["name"]) if "name" in data.files else path.name,
                )
            except ValidationError as exc:
                raise FormatError(path, str(exc), field="control_points") from None

    def subset(self, patches: npt.ArrayLike) -> "PatchNet":
        """A new net of the selected patches (topology recomputed)."""
        patches = np.asarray(patches)
        return PatchNet(
            self.control_points[patches], self.uv[patches], self.lightmap_rect[patches], self.tol, self.name
        )


def _extent(cp: np.ndarray, op: np.ufunc) -> np.ndarray:
    """``op`` (np.minimum / np.maximum) over every control point of ``cp`` (n, 4, 4, 3) -> (3,): over
    rows of 48 contiguous values (one patch) first, then the 16 points."""
    return op.reduce(op.reduce(cp.reshape(-1, 48), axis=0).reshape(16, 3), axis=0)


def _fold(cp: np.ndarray, op: np.ufunc) -> np.ndarray:
    """``op`` (np.minimum / np.maximum) over the 16 control points of each patch: ``cp`` (n, 4, 4, 3)
    -> (n, 3), by halving the points four times (elementwise on contiguous halves)."""
    a = cp.reshape(len(cp), 16, 3)
    for half in (8, 4, 2, 1):
        a = op(a[:, :half], a[:, half:2 * half])
    return a[:, 0]


def default_lightmap_rects(n: int, res: int = 8, gutter: int = 1) -> np.ndarray:
    """Light-map tiles for ``n`` patches in a square atlas of ``res x res`` tiles with gutters.

    Each tile occupies ``res + 2 * gutter`` texels; parameter (0, 0) maps to the centre of the
    tile's first texel and (1, 1) to the centre of its last, so bilinear filtering never reads a
    neighbour's texels.  Returns ``(n, 4)`` float32 ``(u0, v0, u1, v1)``.
    """
    cell = res + 2 * gutter
    cols = int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / cols))
    w, h = cols * cell, rows * cell
    k = np.arange(n)
    tx, ty = k % cols, k // cols
    x0 = tx * cell + gutter + 0.5
    y0 = ty * cell + gutter + 0.5
    return np.stack([x0 / w, y0 / h, (x0 + res - 1) / w, (y0 + res - 1) / h], axis=1).astype(np.float32)
