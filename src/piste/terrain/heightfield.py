"""The least-squares solve behind :func:`piste.terrain.fit.fit_heightfield`: height field -> control points.

It returns arrays (:class:`FittedGrid`), not a net, so that both :mod:`piste.terrain.net`
(``PatchNet.from_heightfield``) and :mod:`piste.terrain.fit` can use it without importing each other.
Fit a net of bicubic Bézier patches to a height field by global least squares.

Layout
------
``z`` is an ``(H, W)`` height field: row ``r`` lies at ``y = origin[1] + r * dy``, column ``c`` at
``x = origin[0] + c * dx`` (Z up).  With ``s = samples_per_patch`` each patch spans ``s`` sample
*intervals* in x and in y (``(s+1)^2`` samples, the ones on its rim shared with its neighbours), so
the net has ``Px = (W - 1) // s`` by ``Py = (H - 1) // s`` patches (``edge="crop"``: the last
``(W - 1) % s`` columns / ``(H - 1) % s`` rows are dropped) or ``ceil((W - 1) / s)`` by
``ceil((H - 1) / s)`` (``edge="pad"``: the field is extended by repeating its last row/column).
Patch ``py * Px + px`` covers columns ``px*s .. (px+1)*s`` and rows ``py*s .. (py+1)*s``; ``u`` runs
along +x, ``v`` along +y, so normals (``du x dv``) point up.

Control points
--------------
x and y control points lie on the regular grid at thirds of the patch, so x(u) and y(v) are exactly
linear and sample ``k`` sits at parameter ``k / s`` of its patch.  The z control points form one
global ``(3 Py + 1, 3 Px + 1)`` grid: the control points on a patch boundary are *one* unknown shared
by both patches, so the net is C0 by construction and the welded :class:`PatchNet` has zero seam gap.

The least-squares problem ``min || (Ay ⊗ Ax) vec(Z) - vec(z) ||`` has a Kronecker-structured sparse
matrix (``Ax``: ``(W', 3 Px + 1)`` sparse, the cubic Bernstein weights of each sample column); its
normal equations separate into two small sparse banded SPD systems,
``Z = (Ayᵀ Ay)⁻¹ Ayᵀ z Ax (Axᵀ Ax)⁻¹``, solved with a sparse LU (``method="separable"``, the
default).  ``method="sparse"`` assembles the full ``(H' W', Ny Nx)`` sparse matrix and solves its
normal equations with ``spsolve``: the same solution, for checks (and slower).

``smooth`` raises the continuity across seams: ``True`` / ``"c1"`` ties each seam's neighbouring
control points to be collinear and evenly spaced (C1: no slope jumps, so no creases in baked
lighting); ``"c2"`` fits a uniform cubic B-spline (knots at the patch boundaries) and converts it
exactly to Bézier form.  Both keep the separable structure (the Bézier sample matrix times a sparse
continuity map) and have fewer degrees of freedom, hence a higher RMSE.

Measured on matplotlib's ``jacksboro_fault_dem.npz`` (344 x 403 samples, ~75 x 93 m, 840 m relief;
8,500 patches of 4x4 sample intervals, every covered sample counted once): C0 RMSE 2.00 m, max
14.1 m (0.3 s); C1 RMSE 3.7 m; C2 RMSE 10.4 m (see ``tests/terrain/test_fit.py``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ValidationError
from piste.terrain.bezier import bernstein

log = logging.getLogger(__name__)

__all__ = ["FittedGrid", "fit_control_points", "bezier_basis_matrix", "c1_to_bezier", "bspline_to_bezier",
           "single_threaded"]

_PIN_LOCK = threading.Lock()
_PIN_STATE: dict = {"depth": 0, "limiter": None}


@contextmanager
def single_threaded() -> Iterator[None]:
    """Run the enclosed numeric work with every BLAS / OpenMP pool of this process at one thread.

    A multi-threaded OpenBLAS splits a matrix product or a factorisation into blocks whose partial
    sums are added in an order that depends on the thread count, so the same fit can differ in its
    last bits (~1e-14) between a multi-threaded process and a single-threaded Dask worker.  Pinned,
    every process computes the same bits whatever its core count or worker layout.

    Re-entrant and safe across threads of one process (a Dask worker with several threads): the
    pools are pinned by the first caller in and restored by the last one out, so no task ever runs
    while another task's exit has raised the limit again.  Needs ``threadpoolctl`` (a dependency).
    """
    with _PIN_LOCK:
        if _PIN_STATE["depth"] == 0:
            from threadpoolctl import threadpool_limits

            _PIN_STATE["limiter"] = threadpool_limits(limits=1)
        _PIN_STATE["depth"] += 1
    try:
        yield
    finally:
        with _PIN_LOCK:
            _PIN_STATE["depth"] -= 1
            if _PIN_STATE["depth"] == 0:
                limiter, _PIN_STATE["limiter"] = _PIN_STATE["limiter"], None
                limiter.restore_original_limits()


def _pair(value: Any, what: str) -> tuple[float, float]:
    arr = np.asarray(value, dtype=np.float64).ravel()
    if arr.size == 1:
        arr = np.repeat(arr, 2)
    if arr.size != 2 or not np.isfinite(arr).all():
        raise ValidationError(f"fit_heightfield: {what} must be a finite number or a pair (x, y), got {value!r}")
    return float(arr[0]), float(arr[1])


def bezier_basis_matrix(n_patches: int, s: int) -> Any:
    """Sample matrix of a C0 piecewise-cubic Bézier curve (1-D), sparse CSR ``(n_patches*s + 1, 3*n_patches + 1)``.

    Row ``k`` holds the Bernstein weights of sample ``k`` (at global parameter ``k / s``) on the four
    control points of its segment; segment ``p`` owns columns ``3p .. 3p+3`` (``3p`` and ``3p + 3`` are
    shared with its neighbours).
    """
    from scipy.sparse import csr_matrix

    k = np.arange(n_patches * s + 1)
    seg = np.minimum(k // s, n_patches - 1)
    t = k / s - seg
    w = bernstein(t)  # (n, 4)
    cols = 3 * seg[:, None] + np.arange(4)
    rows = np.repeat(k, 4)
    return csr_matrix((w.ravel(), (rows, cols.ravel())), shape=(len(k), 3 * n_patches + 1))


def c1_to_bezier(n_patches: int) -> Any:
    """C1 piecewise-cubic Bézier coefficients to all Bézier control points (uniform segments).

    Unknowns (``2*n_patches + 2``): the ``n_patches + 1`` node points ``b[3p]``, then the outgoing
    handle ``b[3p + 1]`` of every segment, then the last incoming handle ``b[3P - 1]``.  Every other
    incoming handle is the mirror ``b[3p - 1] = 2 b[3p] - b[3p + 1]`` (equal parameter lengths, so this
    is exactly C1).  Returns a sparse ``(3*n_patches + 1, 2*n_patches + 2)`` matrix.
    """
    from scipy.sparse import csr_matrix

    p_ = n_patches
    nodes = np.arange(p_ + 1)
    out = np.arange(p_)
    inner = np.arange(1, p_)
    rows = np.concatenate([3 * nodes, 3 * out + 1, [3 * p_ - 1], 3 * inner - 1, 3 * inner - 1])
    cols = np.concatenate([nodes, p_ + 1 + out, [2 * p_ + 1], inner, p_ + 1 + inner])
    vals = np.concatenate([np.ones(p_ + 1), np.ones(p_), [1.0], np.full(p_ - 1, 2.0), np.full(p_ - 1, -1.0)])
    return csr_matrix((vals, (rows, cols)), shape=(3 * p_ + 1, 2 * p_ + 2))


def bspline_to_bezier(n_patches: int) -> Any:
    """Exact conversion of uniform cubic B-spline coefficients to C0 Bézier control points.

    Returns a sparse ``(3*n_patches + 1, n_patches + 3)`` matrix ``C``: segment ``p`` with B-spline
    points ``d[p..p+3]`` has Bézier points ``((d0+4d1+d2)/6, (2d1+d2)/3, (d1+2d2)/3, (d1+4d2+d3)/6)``.
    """
    from scipy.sparse import csr_matrix

    local = np.array(
        [[1 / 6, 4 / 6, 1 / 6, 0.0], [0.0, 2 / 3, 1 / 3, 0.0], [0.0, 1 / 3, 2 / 3, 0.0], [0.0, 1 / 6, 4 / 6, 1 / 6]]
    )
    p = np.arange(n_patches)
    # rows 3p, 3p+1, 3p+2 from segment p; the last row 3P from the last segment's end point
    rows = (3 * p[:, None] + np.arange(3))[:, :, None].repeat(4, axis=2)
    cols = (p[:, None, None] + np.arange(4)[None, None, :]).repeat(3, axis=1)
    vals = np.broadcast_to(local[:3], (n_patches, 3, 4))
    rows = np.concatenate([rows.ravel(), np.full(4, 3 * n_patches)])
    cols = np.concatenate([cols.ravel(), n_patches - 1 + np.arange(4)])
    vals = np.concatenate([vals.ravel(), local[3]])
    return csr_matrix((vals, (rows, cols)), shape=(3 * n_patches + 1, n_patches + 3))


def _continuity_map(n_patches: int, continuity: str) -> Any:
    """Sparse map from the free coefficients to the ``3*n_patches + 1`` Bézier control points (None for C0)."""
    if continuity == "c1":
        return c1_to_bezier(n_patches)
    if continuity == "c2":
        return bspline_to_bezier(n_patches)
    return None


def _normal_solve(a: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``(aᵀ a) x = rhs`` for a sparse ``a`` and a dense ``(m, k)`` right-hand side."""
    from scipy.sparse.linalg import splu

    return splu((a.T @ a).tocsc()).solve(np.ascontiguousarray(rhs))


def _check_field(z: npt.ArrayLike) -> np.ndarray:
    try:
        z = np.asarray(z, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"fit_heightfield: field 'z' must be a numeric (H, W) array ({exc})") from None
    if z.ndim != 2:
        raise ValidationError(f"fit_heightfield: field 'z' must be a 2-D (H, W) height field, got shape {z.shape}")
    bad = ~np.isfinite(z)
    if bad.any():
        r, c = (int(v) for v in np.argwhere(bad)[0])
        raise ValidationError(
            f"fit_heightfield: field 'z' has {int(bad.sum())} non-finite sample(s), first at row {r}, column {c} "
            f"({z[r, c]}): expected finite heights (fill holes before fitting)"
        )
    return z


@dataclass(frozen=True)
class FittedGrid:
    """The fitted patches, before they become a :class:`piste.terrain.net.PatchNet`.

    control_points : (n, 4, 4, 3) float64, patch ``py * Px + px``;  uv : (n, 4, 2) float64 corner UVs
    tol : weld tolerance for the net;  grid_shape : (Py, Px) patches per column and per row
    """

    control_points: np.ndarray
    uv: np.ndarray
    tol: float
    grid_shape: tuple


def fit_control_points(
    z: npt.ArrayLike,
    spacing: float | tuple[float, float],
    samples_per_patch: int = 4,
    origin: npt.ArrayLike = (0.0, 0.0),
    uv_scale: float | tuple[float, float] | None = None,
    smooth: bool = False,
    edge: str = "crop",
    method: str = "separable",
    progress: bool = False,
    name: str = "heightfield",
    tol: float | None = None,
) -> FittedGrid:
    """Fit a C0 (or, with ``smooth``, C2) bicubic Bézier net to a height field: the patches' control
    points (:func:`piste.terrain.fit.fit_heightfield` wraps them in a :class:`PatchNet`).

    Parameters
    ----------
    z : (H, W) float array, heights; row index along +y, column index along +x
    spacing : float or (dx, dy), sample spacing in metres
    samples_per_patch : sample intervals per patch side (>= 3; 4 is the usual choice)
    origin : (x, y) of sample ``z[0, 0]``
    uv_scale : float or (su, sv): base-texture UV = world (x, y) relative to ``origin`` divided by
        this; default: the patch size (one texture repeat per patch)
    smooth : fit a C2 uniform cubic B-spline and convert it exactly to Bézier patches
    edge : ``"crop"`` (drop samples past the last whole patch) or ``"pad"`` (repeat the last
        row/column up to a whole patch)
    method : ``"separable"`` (default) or ``"sparse"`` (assemble and solve the full sparse system;
        same result, slower; for checks)
    progress : print the stages to stderr
    name : unused here (the net's name; kept so that the keywords match ``fit_heightfield``)
    tol : weld tolerance for the net (default ``1e-6`` of the patch size)

    Returns
    -------
    FittedGrid of ``Px * Py`` patches, patch ``py * Px + px``; control points ``(n, 4, 4, 3)`` float64.

    Raises
    ------
    ValidationError
        ``z`` not 2-D, non-finite samples in ``z`` (names the first), fewer than 2 patches of samples,
        bad ``spacing``/``origin``/``uv_scale``/``samples_per_patch``/``edge``/``method``.
    """
    t0 = time.perf_counter()

    def stage(msg: str) -> None:
        log.log(logging.INFO if progress else logging.DEBUG, "fit_heightfield: %s (%.2f s)", msg,
                time.perf_counter() - t0)

    z = _check_field(z)
    dx, dy = _pair(spacing, "spacing")
    if dx <= 0 or dy <= 0:
        raise ValidationError(f"fit_heightfield: spacing must be positive, got {spacing!r}")
    ox, oy = _pair(origin, "origin")
    s = int(samples_per_patch)
    if s != samples_per_patch or s < 3:
        raise ValidationError(
            f"fit_heightfield: samples_per_patch must be an integer >= 3 (a cubic needs 4 samples a segment), "
            f"got {samples_per_patch!r}"
        )
    continuity = {False: "c0", None: "c0", True: "c1"}.get(smooth, smooth) if not isinstance(smooth, str) else smooth.lower()
    if continuity not in ("c0", "c1", "c2"):
        raise ValidationError(f"fit_heightfield: smooth must be False/'c0', True/'c1' or 'c2', got {smooth!r}")
    if edge not in ("crop", "pad"):
        raise ValidationError(f"fit_heightfield: edge must be 'crop' or 'pad', got {edge!r}")
    if method not in ("separable", "sparse"):
        raise ValidationError(f"fit_heightfield: method must be 'separable' or 'sparse', got {method!r}")
    h, w = z.shape
    if edge == "crop":
        px, py = (w - 1) // s, (h - 1) // s
    else:
        px, py = -(-(w - 1) // s), -(-(h - 1) // s)
    if px < 1 or py < 1 or px * py < 2:
        raise ValidationError(
            f"fit_heightfield: field 'z' of shape {z.shape} holds {max(px, 0)} x {max(py, 0)} patches of "
            f"{s} sample intervals: expected at least 2 patches (at least {s + 1} x {2 * s + 1} samples)"
        )
    wn, hn = px * s + 1, py * s + 1
    if edge == "crop":
        zz = z[:hn, :wn]
    else:
        zz = np.pad(z, ((0, hn - h), (0, wn - w)), mode="edge")
    # fit heights relative to their mean: better conditioned, exact either way
    z_mean = float(zz.mean())
    zz = zz - z_mean
    stage(f"{px} x {py} patches from {zz.shape[0]} x {zz.shape[1]} samples")

    # A = (Bézier sample matrix) @ (continuity map T); the Bézier z grid is Ty coef Txᵀ
    tx, ty = _continuity_map(px, continuity), _continuity_map(py, continuity)
    ax_, ay_ = bezier_basis_matrix(px, s), bezier_basis_matrix(py, s)
    if tx is not None:
        ax_, ay_ = (ax_ @ tx).tocsr(), (ay_ @ ty).tocsr()
    if method == "separable":
        # coef = Gy⁻¹ (Ayᵀ z Ax) Gx⁻¹ with G = Aᵀ A: solve along x on the transposed rhs, then along y
        rhs = np.asarray(ax_.T @ np.asarray(ay_.T @ zz).T).T  # (Ny, Nx) = Ayᵀ z Ax
        tmp = _normal_solve(ax_, rhs.T)  # (Nx, Ny) = Gx⁻¹ (Ayᵀ z Ax)ᵀ
        coef = _normal_solve(ay_, tmp.T)  # (Ny, Nx)
    else:
        from scipy.sparse import kron
        from scipy.sparse.linalg import spsolve

        a = kron(ay_, ax_, format="csr")  # row r*wn + c, column j*Nx + i
        coef = spsolve((a.T @ a).tocsc(), a.T @ zz.ravel()).reshape(ay_.shape[1], ax_.shape[1])
    stage(f"solved {coef.size} unknowns ({method}, {continuity.upper()})")
    if tx is not None:
        coef = np.asarray(ty @ np.asarray(tx @ coef.T).T)  # (3Py+1, 3Px+1)
    zc = coef + z_mean

    # assemble (n, 4, 4, 3): patch (py, px), P[i, j] = (X[3px+i], Y[3py+j], Z[3py+j, 3px+i])
    lx, ly = s * dx, s * dy
    xs = ox + np.arange(3 * px + 1) / 3.0 * lx
    ys = oy + np.arange(3 * py + 1) / 3.0 * ly
    xs[::3] = ox + np.arange(px + 1) * lx  # exact corner positions
    ys[::3] = oy + np.arange(py + 1) * ly
    ii = 3 * np.arange(px)[None, :, None, None] + np.arange(4)[None, None, :, None]  # (1, px, 4, 1)
    jj = 3 * np.arange(py)[:, None, None, None] + np.arange(4)[None, None, None, :]  # (py, 1, 1, 4)
    shape = (py, px, 4, 4)
    cp = np.empty(shape + (3,))
    cp[..., 0] = np.broadcast_to(xs[ii], shape)
    cp[..., 1] = np.broadcast_to(ys[jj], shape)
    cp[..., 2] = zc[jj, ii]
    cp = cp.reshape(px * py, 4, 4, 3)

    su, sv = (lx, ly) if uv_scale is None else _pair(uv_scale, "uv_scale")
    if su == 0 or sv == 0:
        raise ValidationError(f"fit_heightfield: uv_scale must be non-zero, got {uv_scale!r}")
    corners = cp[:, [0, 3, 3, 0], [0, 0, 3, 3], :2]  # c0..c3, (n, 4, 2)
    uv = np.stack([(corners[..., 0] - ox) / su, (corners[..., 1] - oy) / sv], axis=-1)
    if tol is None:
        tol = 1e-6 * min(lx, ly)
    return FittedGrid(cp, uv, float(tol), (py, px))


