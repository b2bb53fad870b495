"""Bicubic Bézier basis, the talk's matrix form, and pre-computed blend tables.

A patch is 16 control points ``P[i, j]`` (``i`` along ``u``, ``j`` along ``v``)::

    Q(u, v) = sum_ij P[i, j] b_i(u) b_j(v)
            = [u^3 u^2 u 1] M P M^T [v^3 v^2 v 1]^T          (the talk's "VU friendly" form)

with ``M`` the Bézier basis matrix :data:`BEZIER_M`.  Evaluating many parameter points of many
patches is one matrix product of the packed control points ``(k*3, 16)`` with a blend table
``(16, S)`` whose column ``s`` is ``kron(b(u_s), b(v_s))``: the talk's pre-calculated blend tables,
here for any number of vertices per edge (4, 6 and 8 are the ones LOD uses).

Edge curves are evaluated on their own with :func:`eval_edges`, whose Bernstein table is
symmetric (``B[k, i] == B[n-1-k, 3-i]`` bit for bit) and whose sum is taken in the symmetric order
``(B0 P0 + B3 P3) + (B1 P1 + B2 P2)``: the result is bit-identical whichever way the edge is
traversed, which is what makes shared edges crack-free.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import numpy.typing as npt

#: The Bézier basis matrix of the talk: ``b(t) = [t^3, t^2, t, 1] @ BEZIER_M``.
BEZIER_M = np.array(
    [[-1.0, 3.0, -3.0, 1.0], [3.0, -6.0, 3.0, 0.0], [-3.0, 3.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]]
)


def bernstein(t: npt.ArrayLike) -> np.ndarray:
    """Cubic Bernstein basis at parameters ``t``.

    Parameters
    ----------
    t : (s,) float array

    Returns
    -------
    (s, 4) float64: ``[(1-t)^3, 3t(1-t)^2, 3t^2(1-t), t^3]``.
    """
    t = np.asarray(t, dtype=np.float64)
    s = 1.0 - t
    return np.stack([s * s * s, 3.0 * t * s * s, 3.0 * t * t * s, t * t * t], axis=-1)


def bernstein_derivative(t: npt.ArrayLike) -> np.ndarray:
    """Derivative of :func:`bernstein` with respect to ``t``, ``(s, 4)`` float64."""
    t = np.asarray(t, dtype=np.float64)
    s = 1.0 - t
    return np.stack([-3.0 * s * s, 3.0 * s * s - 6.0 * t * s, 6.0 * t * s - 3.0 * t * t, 3.0 * t * t], axis=-1)


def power_basis(t: npt.ArrayLike) -> np.ndarray:
    """``[t^3, t^2, t, 1]`` at parameters ``t``, ``(s, 4)`` float64 (the talk's row vector)."""
    t = np.asarray(t, dtype=np.float64)
    return np.stack([t**3, t**2, t, np.ones_like(t)], axis=-1)


def params(n: int) -> np.ndarray:
    """``n`` evenly spaced parameters in [0, 1], exact at both ends, ``(n,)`` float64."""
    if n < 2:
        raise ValueError(f"need at least 2 vertices per edge, got {n}")
    return np.arange(n, dtype=np.float64) / (n - 1)


@lru_cache(maxsize=None)
def edge_table(n: int) -> np.ndarray:
    """Symmetric Bernstein table for ``n`` vertices along an edge, ``(n, 4)`` float64.

    Rows for the second half are the mirrored first half, so ``B[k, i] == B[n-1-k, 3-i]`` exactly.
    """
    b = bernstein(params(n))
    half = (n + 1) // 2
    b[n - half :] = b[:half][::-1, ::-1]
    b[0] = (1.0, 0.0, 0.0, 0.0)
    b[-1] = (0.0, 0.0, 0.0, 1.0)
    b.setflags(write=False)
    return b


def _kron_table(bu: np.ndarray, bv: np.ndarray) -> np.ndarray:
    """``(16, s)`` table with row ``4*i + j`` = ``bu[:, i] * bv[:, j]``."""
    return (bu[:, :, None] * bv[:, None, :]).reshape(len(bu), 16).T


@lru_cache(maxsize=None)
def blend_tables(u: tuple[float, ...], v: tuple[float, ...], dtype: str = "float32") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blend tables for the parameter points ``(u[s], v[s])``.

    Returns ``(T, Tu, Tv)``, each ``(16, s)``: position, d/du and d/dv weights, such that for
    packed control points ``X (k*3, 16)`` the product ``X @ T`` is ``(k*3, s)`` positions.
    """
    ua = np.asarray(u, dtype=np.float64)
    va = np.asarray(v, dtype=np.float64)
    bu, bv = bernstein(ua), bernstein(va)
    du, dv = bernstein_derivative(ua), bernstein_derivative(va)
    t, tu, tv = (np.ascontiguousarray(_kron_table(a, b), dtype=dtype) for a, b in ((bu, bv), (du, bv), (bu, dv)))
    for table in (t, tu, tv):
        table.setflags(write=False)
    return t, tu, tv


def grid_params(n: int, inner: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Parameters of an ``n x n`` grid (or of its ``(n-2) x (n-2)`` interior when ``inner``).

    Returns ``(u, v)``, each ``(s,)`` float64, row-major with ``u`` fastest: index ``j * w + i``
    is ``(u_i, v_j)`` where ``w`` is the row width.
    """
    t = params(n)
    if inner:
        t = t[1:-1]
    v, u = np.meshgrid(t, t, indexing="ij")
    return u.ravel(), v.ravel()


def pack_control_points(cp: np.ndarray, dtype: npt.DTypeLike = np.float32) -> np.ndarray:
    """Pack control points for blend-table products.

    Parameters
    ----------
    cp : (n, 4, 4, 3) float array

    Returns
    -------
    (n, 3, 16) array of ``dtype``: coordinate-major rows of the 16 control points.
    """
    cp = np.asarray(cp)
    return np.ascontiguousarray(cp.reshape(len(cp), 16, 3).transpose(0, 2, 1), dtype=dtype)


def eval_packed(packed: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Evaluate packed patches with one matrix product.

    Parameters
    ----------
    packed : (k, 3, 16) float array, from :func:`pack_control_points`
    table : (16, s) blend table

    Returns
    -------
    (k, s, 3) array.
    """
    k = len(packed)
    out = packed.reshape(k * 3, 16) @ table
    return out.reshape(k, 3, -1).transpose(0, 2, 1)


def unit_normals(du: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``du x dv`` normalised; returns ``(normals, ok)`` where ``ok`` marks non-degenerate ones.

    ``du, dv`` are ``(..., 3)``; degenerate (zero-length) normals are returned as zeros with
    ``ok`` False so callers can substitute a limit normal.
    """
    n = np.cross(du, dv)
    length = np.sqrt(np.einsum("...i,...i->...", n, n))
    # degenerate when |du x dv| is tiny against the larger tangent squared: a collapsed edge has
    # one tangent that is pure rounding noise, which a test relative to |du| |dv| would miss
    big = np.maximum(np.einsum("...i,...i->...", du, du), np.einsum("...i,...i->...", dv, dv))
    ok = length > 1e-7 * np.maximum(big, 1e-300)
    n = n / np.where(ok, length, 1.0)[..., None]
    n[~ok] = 0.0
    return n, ok


def evaluate(cp: np.ndarray, u: npt.ArrayLike, v: npt.ArrayLike, normals: bool = True,
             dtype: npt.DTypeLike = np.float64) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Evaluate every patch at the same parameter points (the reference path, float64).

    Parameters
    ----------
    cp : (n, 4, 4, 3) control points
    u, v : (s,) parameters
    normals : also return unit normals (degenerate points get a limit normal)

    Returns
    -------
    positions (n, s, 3) and, when ``normals``, normals (n, s, 3).
    """
    u = tuple(float(x) for x in np.atleast_1d(u))
    v = tuple(float(x) for x in np.atleast_1d(v))
    dt = np.dtype(dtype).name
    t, tu, tv = blend_tables(u, v, dt)
    packed = pack_control_points(cp, dtype)
    pos = eval_packed(packed, t)
    if not normals:
        return pos
    nrm, ok = unit_normals(eval_packed(packed, tu), eval_packed(packed, tv))
    if not ok.all():
        nrm = _limit_normals(packed, np.asarray(u), np.asarray(v), nrm, ok, dt)
    return pos, nrm


def _limit_normals(packed: np.ndarray, u: np.ndarray, v: np.ndarray, nrm: np.ndarray, ok: np.ndarray, dtype: npt.DTypeLike,
                   steps: tuple[float, ...] = (1e-4, 1e-3, 1e-2, 1e-1)) -> np.ndarray:
    """Replace degenerate normals by the normal a little way towards the patch centre.

    At a collapsed edge (the teapot's lid apex) ``du x dv`` vanishes; the limit of the normal as
    the point approaches along the patch is well defined and is what neighbours see.
    """
    nrm = nrm.copy()
    bad_p, bad_s = np.nonzero(~ok)
    for eps in steps:
        if len(bad_p) == 0:
            break
        uu = u[bad_s] + eps * (0.5 - u[bad_s])
        vv = v[bad_s] + eps * (0.5 - v[bad_s])
        bu, bv = bernstein(uu), bernstein(vv)
        du, dv = bernstein_derivative(uu), bernstein_derivative(vv)
        x = packed[bad_p].astype(np.float64).reshape(len(bad_p), 3, 4, 4)
        tu = np.einsum("kcij,ki,kj->kc", x, du, bv)
        tv = np.einsum("kcij,ki,kj->kc", x, bu, dv)
        n2, ok2 = unit_normals(tu, tv)
        nrm[bad_p[ok2], bad_s[ok2]] = n2[ok2]
        bad_p, bad_s = bad_p[~ok2], bad_s[~ok2]
    if len(bad_p):  # fully collapsed patch: no surface, pick +z
        nrm[bad_p, bad_s] = (0.0, 0.0, 1.0)
    return nrm


def eval_edges(edge_cp: np.ndarray, n: int, interior: bool = True) -> np.ndarray:
    """Evaluate cubic edge curves at ``n`` vertices each, symmetrically.

    Parameters
    ----------
    edge_cp : (e, 4, 3) control points of each edge curve
    n : vertices per edge
    interior : return only the ``n - 2`` interior vertices (the corners are control points)

    Returns
    -------
    (e, n, 3) or (e, n - 2, 3) array, same dtype as ``edge_cp``; reversing an edge's control points
    reverses its output exactly (bit for bit).
    """
    b = edge_table(n).astype(edge_cp.dtype)
    if interior:
        b = b[1:-1]
    c = np.moveaxis(np.asarray(edge_cp), 1, 0).copy()  # (4, e, 3): each control point contiguous
    out = np.empty((len(b), *c.shape[1:]), dtype=c.dtype)
    for k, (b0, b1, b2, b3) in enumerate(b):
        np.add(b0 * c[0] + b3 * c[3], b1 * c[1] + b2 * c[2], out=out[k])
    return np.moveaxis(out, 0, 1)


def eval_power_form(cp: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The talk's literal matrix form ``U M P M^T V^T`` (float64), for checks and comparison.

    Parameters
    ----------
    cp : (n, 4, 4, 3);  u, v : (s,)

    Returns
    -------
    (n, s, 3) float64.  Not used for tessellation: shared edges evaluated this way are not
    bit-identical between neighbours.
    """
    cp = np.asarray(cp, dtype=np.float64)
    coeff = np.einsum("ai,nijc,bj->nabc", BEZIER_M, cp, BEZIER_M)  # M P M^T, (n, 4, 4, 3)
    pu, pv = power_basis(u), power_basis(v)
    return np.einsum("sa,nabc,sb->nsc", pu, coeff, pv)
