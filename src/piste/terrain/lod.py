"""Per-edge distance LOD and view-frustum culling of patches.

The talk: "Distance based heuristic applied to each edge, evaluated to 4, 6 or 8 vertices per
edge".  The level is a function of the edge alone (its midpoint's distance to the eye), so the
two patches on a shared edge always agree: crack-freedom needs nothing more.

Error-driven levels: flat (below the coarsest) and coarse
---------------------------------------------------------
Every patch has precomputed errors (:func:`_patch_errors`: the largest distance between the surface
and its uniform level-``n`` mesh at the same ``(u, v)``, over the level-4 and 8 grid parameters) for
the **flat level** (2 vertices a side: the corner quad, triangles ``(0, 1, 2)``, ``(0, 2, 3)``) and the
coarsest level, and each edge the larger error of its (up to two) patches and the union of their
control-point boxes (:func:`flat_bounds`, :func:`level_errors`).  With ``lim = flat_error * d``, ``d``
the eye's distance to that box (the nearest any point of either patch can be), an edge is drawn
flat when its flat error is under ``lim``, else at the coarsest level when that level's error is
(whatever its distance band), else as the distance says: the on-screen error stays under
``flat_error`` radians (:data:`FLAT_ERROR`: 0.5 px at 640x448 with a 60-degree field of view).  A
patch whose four sides are flat is its 2 corner triangles; one with some flat sides is a glue patch
whose strips on those sides zip to the straight edge.  Still a function of the edge alone (the same
arithmetic on the same per-edge inputs in both patches): crack-free as before.  An edge made
coarser by its error does not morph to it (the step is under ``flat_error`` on screen).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, ValidationError
from piste.terrain.bezier import blend_tables, params
from piste.transforms import cull_boxes, frustum_planes, look_at, perspective

#: piste.terrain.net.PatchNet, typed Any here: net imports this module (an import back is a cycle)
_Net = Any

#: default thresholds for a course in metres: edges nearer than ``near`` get 8 vertices, nearer
#: than ``far`` 6, the rest 4 (tuned so a view down the default course gives the talk's mix)
DEFAULT_NEAR = 60.0
DEFAULT_FAR = 180.0
LEVELS = (4, 6, 8)
#: the flat level's vertices per edge (the corners alone)
FLAT_LEVEL = 2
#: default largest on-screen error of a flat edge's patches, in radians seen from the eye (0.5 px at
#: 640x448 with a 60-degree vertical field of view: 448 / (2 tan 30 deg) = 388 px a radian)
FLAT_ERROR = 0.5 / (448 / (2.0 * np.tan(np.radians(30.0))))


def _grid_weights(c: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(k, c^2)``: the points ``(u, v)`` as barycentric blends of the uniform level-``c`` grid's
    points (column ``j c + i`` at ``(i, j) / (c - 1)``), in the triangle of the grid that holds each
    (cells split along ``(i, j)-(i+1, j+1)``, the tessellator's uniform triangulation)."""
    x, y = u * (c - 1), v * (c - 1)
    ci = np.minimum(np.floor(x).astype(np.int64), c - 2)
    cj = np.minimum(np.floor(y).astype(np.int64), c - 2)
    fx, fy = x - ci, y - cj
    lower = fx >= fy
    w = np.zeros((len(u), c * c))
    r = np.arange(len(u))
    np.add.at(w, (r, cj * c + ci), np.where(lower, 1 - fx, 1 - fy))
    np.add.at(w, (r, cj * c + ci + 1), np.where(lower, fx - fy, 0.0))
    np.add.at(w, (r, (cj + 1) * c + ci + 1), np.where(lower, fy, fx))
    np.add.at(w, (r, (cj + 1) * c + ci), np.where(lower, 0.0, fy - fx))
    return w


def _patch_errors(net: _Net, n: int, chunk: int = 1024) -> np.ndarray:
    """Per patch, the largest distance between the surface and its uniform level-``n`` mesh (for
    ``n = 2`` the corner quad, triangles (0, 1, 2), (0, 2, 3)) at the same parameter, over the union of
    the level-4 and 8 grid parameters: ``(N,)`` float64 (model units).  Both are linear in the
    control points, so the difference is one table ``(16, k)`` (its columns sum to 0: no offset of the
    net matters) and the errors one product."""
    t1 = np.sort(np.concatenate([params(4), params(8)]))
    t1 = t1[np.r_[True, np.diff(t1) > 0]]  # np.unique's values, without importing numpy.ma (a cold start's 15-26 ms)
    vv, uu = np.meshgrid(t1, t1, indexing="ij")
    u, v = uu.ravel(), vv.ravel()
    t, _, _ = blend_tables(tuple(u), tuple(v), "float64")  # (16, k): the surface at (u, v)
    g = params(n)
    gv, gu = np.meshgrid(g, g, indexing="ij")
    tg, _, _ = blend_tables(tuple(gu.ravel()), tuple(gv.ravel()), "float64")  # (16, n^2): the grid points
    d = (t - tg @ _grid_weights(n, u, v).T).astype(np.float32)  # minus the level-n mesh at (u, v)
    cp_all = np.asarray(net.control_points)
    N = len(net)
    out = np.empty(N, dtype=np.float64)
    for a in range(0, N, chunk):
        b = min(a + chunk, N)
        k = b - a
        # float32 relative to each patch's first control point (errors of ~1e-6 of a patch's size), and
        # einsum, not matmul: a first frame computes these, and BLAS's worker threads, spinning after a
        # product, took ~90 ms of CPU from that frame on 2 cores (einsum's loops are single-threaded)
        c = cp_all[a:b].reshape(k, 16, 3)
        c = (c - c[:, :1]).astype(np.float32)
        sq: np.ndarray | None = None
        for x in range(3):
            e = np.einsum("kc,cm->km", np.ascontiguousarray(c[:, :, x]), d, optimize=False)  # (k, m)
            e *= e
            sq = e if sq is None else np.add(sq, e, out=sq)
        assert sq is not None
        out[a:b] = np.sqrt(sq.max(axis=1).astype(np.float64))
    return out


def _flat_patch_errors(net: _Net) -> np.ndarray:
    """Per patch, the largest distance between the surface and its corner quad: ``(N,)`` float64."""
    return _patch_errors(net, FLAT_LEVEL)


def _edge_max(net: _Net, per_patch: np.ndarray) -> np.ndarray:
    """The larger of an edge's (up to two) patches' values, ``(e,)``."""
    ep = np.asarray(net.edge_patches, dtype=np.int64)
    other = np.where(ep[:, 1] >= 0, ep[:, 1], ep[:, 0])
    return np.ascontiguousarray(np.maximum(per_patch[ep[:, 0]], per_patch[other]))


#: the levels whose per-patch errors a build stores (:func:`patch_error_table`, the bundle's
#: ``lod_errors/patch_errors``): the flat level and the coarsest, what a frame decides on
STORED_ERROR_LEVELS = (FLAT_LEVEL, LEVELS[0])


def patch_error_table(net: _Net, levels: tuple[int, ...] = STORED_ERROR_LEVELS) -> np.ndarray:
    """Per patch, the errors of its uniform level-``n`` meshes for each of ``levels``
    (:func:`_patch_errors`): ``(N, len(levels))`` float64, what a build stores so that a fresh
    process's first frame need not compute them (10-30 ms on the default course)."""
    out = np.empty((len(net), len(levels)), dtype=np.float64)
    for i, n in enumerate(levels):
        out[:, i] = _patch_errors(net, int(n))
    return out


def keep_patch_errors(net: _Net, table: npt.ArrayLike, levels: tuple[int, ...] = STORED_ERROR_LEVELS) -> None:
    """Keep the stored per-patch error ``table`` (:func:`patch_error_table`: ``(N, len(levels))``
    float64, finite, >= 0) on ``net``: :func:`level_errors` and :func:`flat_bounds` then take their
    per-patch errors from it instead of computing them.  Raises
    :class:`~piste.errors.ValidationError` saying what is wrong when it does not fit the net."""
    t = np.asarray(table)
    want = (len(net), len(levels))
    if t.dtype != np.float64 or t.shape != want:
        raise ValidationError(f"{getattr(net, 'name', 'terrain')}: patch error table must be {list(want)} float64 "
                              f"(patches x levels {list(levels)}), got {list(t.shape)} {t.dtype}")
    if t.size and not (np.all(np.isfinite(t)) and t.min() >= 0.0):
        raise ValidationError(f"{getattr(net, 'name', 'terrain')}: patch error table must be finite and >= 0")
    net.__dict__["_stored_patch_errors"] = {int(n): t[:, i] for i, n in enumerate(levels)}


def level_errors(net: _Net, n: int) -> np.ndarray:
    """Per edge, the larger error of its patches' uniform level-``n`` meshes (:func:`_patch_errors`,
    or the table kept by :func:`keep_patch_errors`), ``(e,)`` float64; computed once per level and
    kept on the net."""
    store = net.__dict__.setdefault("_level_errors", {})
    e = store.get(int(n))
    if e is None:
        per = net.__dict__.get("_stored_patch_errors", {}).get(int(n))
        e = _edge_max(net, _patch_errors(net, int(n)) if per is None else per)
        store[int(n)] = e
    return e


def kept_patch_bounds(net: _Net) -> tuple[np.ndarray, np.ndarray]:
    """``net.patch_bounds`` computed once for what is kept on the net from it (:func:`flat_bounds`,
    :func:`piste.terrain.cull.patch_tree`: each computed it, ~0.5 ms a call at 2.5k patches) and
    kept on the net like them: ``(min (n, 3), max (n, 3))`` float64."""
    b = net.__dict__.get("_patch_bounds")
    if b is None:
        b = net.__dict__["_patch_bounds"] = net.patch_bounds
    return b


def kept_bounds(net: _Net) -> tuple[np.ndarray, np.ndarray]:
    """``net.bounds`` (the same values: min and max are exact) reduced from :func:`kept_patch_bounds`:
    ``(min (3,), max (3,))`` float64, ~20 us once the patch bounds are kept (``net.bounds`` reads
    every control point: ~0.3-0.7 ms at 2.5k patches)."""
    lo, hi = kept_patch_bounds(net)
    return lo.min(axis=0), hi.max(axis=0)


def flat_bounds(net: _Net) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the flat level decides on, per edge (computed once, kept on the net):
    ``(err (e,) float64, lo (e, 3) float64, hi (e, 3) float64)``: the larger flatness error of the
    edge's patches (:func:`_flat_patch_errors`) and the union of their control-point boxes."""
    fb = net.__dict__.get("_flat_bounds")
    if fb is None:
        err = level_errors(net, FLAT_LEVEL)
        ep = np.asarray(net.edge_patches, dtype=np.int64)
        other = np.where(ep[:, 1] >= 0, ep[:, 1], ep[:, 0])
        plo, phi = kept_patch_bounds(net)
        lo = np.ascontiguousarray(np.minimum(plo[ep[:, 0]], plo[other]), dtype=np.float64)
        hi = np.ascontiguousarray(np.maximum(phi[ep[:, 0]], phi[other]), dtype=np.float64)
        fb = (np.ascontiguousarray(err), lo, hi)
        net.__dict__["_flat_bounds"] = fb
    return fb


def error_limit(net: _Net, eye: npt.ArrayLike, edges: np.ndarray | None = None,
                flat_error: float = FLAT_ERROR) -> np.ndarray:
    """The largest error each edge's patches (all edges, or ``edges``, any shape) may have to be drawn
    coarser from ``eye``: ``flat_error * d``, ``d`` the eye's distance to the edge's box, ``(e,)`` or
    ``edges``' shape, float64 (the same arithmetic as the resident path's compiled LOD)."""
    _, lo, hi = flat_bounds(net)
    if edges is not None:
        lo, hi = lo[edges], hi[edges]
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    g = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    d = np.sqrt(g[..., 0] * g[..., 0] + g[..., 1] * g[..., 1] + g[..., 2] * g[..., 2])
    return float(flat_error) * d


def flat_edges(net: _Net, eye: npt.ArrayLike, edges: np.ndarray | None = None,
               flat_error: float = FLAT_ERROR) -> np.ndarray:
    """Whether each edge (all, or ``edges (k,)``) may be drawn flat from ``eye``: its patches' corner
    quads within :func:`error_limit`; ``(k,)`` bool."""
    err = flat_bounds(net)[0]
    return (err if edges is None else err[edges]) < error_limit(net, eye, edges, flat_error)


def coarse_edges(net: _Net, eye: npt.ArrayLike, edges: np.ndarray | None = None, flat_error: float = FLAT_ERROR,
                 coarse: int = LEVELS[0]) -> np.ndarray:
    """Whether each edge may be drawn at the ``coarse`` level from ``eye`` whatever its distance: its
    patches' uniform ``coarse`` meshes within :func:`error_limit`; ``(k,)`` bool."""
    err = level_errors(net, coarse)
    return (err if edges is None else err[edges]) < error_limit(net, eye, edges, flat_error)


def edge_levels(net: _Net, eye: npt.ArrayLike, near: float = DEFAULT_NEAR, far: float = DEFAULT_FAR,
                levels: tuple[int, ...] = LEVELS,
                flat_error: float | None = FLAT_ERROR) -> np.ndarray:
    """Vertices per edge for a camera at ``eye``.

    Parameters
    ----------
    net : PatchNet
    eye : (3,) camera position
    near, far : distance thresholds (model units): ``d < near`` -> ``levels[2]``,
        ``d < far`` -> ``levels[1]``, else ``levels[0]``
    levels : (coarse, medium, fine) vertices per edge
    flat_error : largest on-screen error (radians) of an edge drawn coarser than its distance says:
        flat (2 vertices) or at ``levels[0]`` (see the module docstring); None or 0: the talk's three
        levels by distance alone

    Returns
    -------
    (e,) int16, one level per edge of ``net`` (collapsed edges get the coarse level, or flat).
    """
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(eye)):
        raise ConfigError(f"eye must be finite, got {eye.tolist()}")
    if not (0 <= near <= far):
        raise ConfigError(f"LOD thresholds must satisfy 0 <= near <= far, got near={near}, far={far}")
    if len(levels) != 3:
        raise ConfigError(f"levels must be (coarse, medium, fine), got {levels}")
    d = np.linalg.norm(net.edge_midpoints() - eye, axis=1)
    out = np.where(d < near, levels[2], np.where(d < far, levels[1], levels[0])).astype(np.int16)
    out[net.edge_degenerate] = levels[0]
    if flat_error:
        if not (np.isfinite(flat_error) and flat_error > 0):
            raise ConfigError(f"flat_error must be a positive angle in radians or None, got {flat_error}")
        lim = error_limit(net, eye, None, flat_error)
        out[(out != levels[0]) & (level_errors(net, levels[0]) < lim)] = levels[0]
        out[flat_bounds(net)[0] < lim] = FLAT_LEVEL
    return out


def visible_patches(net: _Net, eye: npt.ArrayLike, target: npt.ArrayLike, fov_y: float = 60.0,
                    aspect: float = 640 / 448, znear: float = 0.5, zfar: float = 5000.0,
                    up: npt.ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Patches whose control-point bounds intersect the view frustum, ``(p,)`` int64."""
    planes = frustum_planes(perspective(fov_y, aspect, znear, zfar) @ look_at(eye, target, up))
    lo, hi = net.patch_bounds
    return np.nonzero(cull_boxes(((lo + hi) / 2).T, ((hi - lo) / 2).T, planes))[0]
