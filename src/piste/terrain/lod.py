"""Per-edge distance LOD and view-frustum culling of patches.

The talk: "Distance based heuristic applied to each edge, evaluated to 4, 6 or 8 vertices per
edge".  The level is a function of the edge alone (its midpoint's distance to the eye), so the
two patches on a shared edge always agree: crack-freedom needs nothing more.

Flat level (below the coarsest)
-------------------------------
A coarse edge (beyond ``far``) is drawn with **2 vertices** (its corners alone) when the patches on
both its sides are flat enough *as seen from the eye*: every patch has a precomputed error ``err``
(:func:`flat_bounds`: the largest distance between the surface at the level-4 and level-8 grid
points and the patch's corner quad, triangles ``(0, 1, 2)``, ``(0, 2, 3)``, at the same ``(u, v)``),
and each edge the larger error of its (up to two) patches and the union of their control-point
boxes.  The edge goes flat when ``err < flat_error * d``, ``d`` the eye's distance to that box
(the nearest any point of either patch can be): the on-screen error is under ``flat_error``
radians (:data:`FLAT_ERROR`: 0.5 px at 640x448 with a 60-degree field of view).  A patch whose four
sides are flat is drawn as its 2 corner triangles; a patch with some flat sides is a glue patch
whose strips on those sides zip to the straight edge.  Still a function of the edge alone (the same
arithmetic on the same per-edge inputs in both patches): crack-free as before.
"""

from __future__ import annotations

import numpy as np

from piste.errors import ConfigError
from piste.transforms import cull_boxes, frustum_planes, look_at, perspective

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


def _flat_patch_errors(net, chunk: int = 8192) -> np.ndarray:
    """Per patch, the largest distance between the surface and its corner quad (triangles (0, 1, 2),
    (0, 2, 3) in the corners' (u, v) = (0, 0), (1, 0), (1, 1), (0, 1)) at the same parameter, over the
    union of the level-4 and level-8 grid parameters: ``(n,)`` float64 (model units)."""
    from piste.terrain.bezier import blend_tables, pack_control_points, params
    from piste.terrain.net import CORNER_INDEX

    t1 = np.unique(np.concatenate([params(4), params(8)]))
    vv, uu = np.meshgrid(t1, t1, indexing="ij")
    u, v = uu.ravel(), vv.ravel()
    t, _, _ = blend_tables(tuple(u), tuple(v), "float64")  # (16, k): the surface at (u, v)
    # minus the corner quad at (u, v): both linear in the control points, so the difference is one
    # table ``d (16, k)`` (its columns sum to 0: no offset of the net matters)
    lower = u >= v
    w = np.stack([1.0 - np.where(lower, u, v), np.where(lower, u - v, 0.0), np.where(lower, v, u),
                  np.where(lower, 0.0, v - u)])  # (4, k) weights of corners 0..3
    d = t.copy()
    for c in range(4):
        d[CORNER_INDEX[c, 0] * 4 + CORNER_INDEX[c, 1]] -= w[c]
    cp_all = np.asarray(net.control_points)
    n = len(net)
    out = np.empty(n, dtype=np.float64)
    for a in range(0, n, chunk):
        b = min(a + chunk, n)
        k = b - a
        diff = (pack_control_points(cp_all[a:b], np.float64).reshape(k * 3, 16) @ d).reshape(k, 3, -1)
        out[a:b] = np.sqrt((diff * diff).sum(axis=1).max(axis=1))
    return out


def flat_bounds(net) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the flat level decides on, per edge (computed once, kept on the net):
    ``(err (e,) float64, lo (e, 3) float64, hi (e, 3) float64)``: the larger flatness error of the
    edge's patches (:func:`_flat_patch_errors`) and the union of their control-point boxes."""
    fb = net.__dict__.get("_flat_bounds")
    if fb is None:
        perr = _flat_patch_errors(net)
        ep = np.asarray(net.edge_patches, dtype=np.int64)
        other = np.where(ep[:, 1] >= 0, ep[:, 1], ep[:, 0])
        err = np.maximum(perr[ep[:, 0]], perr[other])
        plo, phi = net.patch_bounds
        lo = np.ascontiguousarray(np.minimum(plo[ep[:, 0]], plo[other]), dtype=np.float64)
        hi = np.ascontiguousarray(np.maximum(phi[ep[:, 0]], phi[other]), dtype=np.float64)
        fb = (np.ascontiguousarray(err), lo, hi)
        net.__dict__["_flat_bounds"] = fb
    return fb


def flat_edges(net, eye, edges=None, flat_error: float = FLAT_ERROR) -> np.ndarray:
    """Whether each edge (all, or ``edges (k,)``) may be drawn flat from ``eye``: ``err < flat_error * d``
    with ``d`` the eye's distance to the edge's box (see the module docstring); ``(k,)`` bool.
    The same float64 arithmetic as the resident path's compiled LOD."""
    err, lo, hi = flat_bounds(net)
    if edges is not None:
        err, lo, hi = err[edges], lo[edges], hi[edges]
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    g = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    d = np.sqrt(g[:, 0] * g[:, 0] + g[:, 1] * g[:, 1] + g[:, 2] * g[:, 2])
    return err < float(flat_error) * d


def edge_levels(net, eye, near: float = DEFAULT_NEAR, far: float = DEFAULT_FAR, levels=LEVELS,
                flat_error: float | None = FLAT_ERROR) -> np.ndarray:
    """Vertices per edge for a camera at ``eye``.

    Parameters
    ----------
    net : PatchNet
    eye : (3,) camera position
    near, far : distance thresholds (model units): ``d < near`` -> ``levels[2]``,
        ``d < far`` -> ``levels[1]``, else ``levels[0]``
    levels : (coarse, medium, fine) vertices per edge
    flat_error : largest on-screen error (radians) of a coarse edge drawn flat (2 vertices, see the
        module docstring); None or 0: never flat (the talk's three levels)

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
        coarse = np.nonzero(out == levels[0])[0]
        out[coarse[flat_edges(net, eye, coarse, flat_error)]] = FLAT_LEVEL
    return out


def visible_patches(net, eye, target, fov_y: float = 60.0, aspect: float = 640 / 448, znear: float = 0.5,
                    zfar: float = 5000.0, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Patches whose control-point bounds intersect the view frustum, ``(p,)`` int64."""
    planes = frustum_planes(perspective(fov_y, aspect, znear, zfar) @ look_at(eye, target, up))
    lo, hi = net.patch_bounds
    return np.nonzero(cull_boxes(((lo + hi) / 2).T, ((hi - lo) / 2).T, planes))[0]
