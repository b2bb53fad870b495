"""Per-block stride errors of a far tile, measured against its fitted patches.

A far tile (:func:`piste.render.streaming.far_mesh`) is drawn by blocks of ``FAR_BLOCK x
FAR_BLOCK`` patches, each at a corner stride ``k``: the triangulation of every ``k``-th patch
corner (the tile's last row and column always kept), two triangles a cell split along the
``(r, c) -> (r+1, c+1)`` diagonal.  :func:`block_stride_errors` gives, for every block and
stride, the largest vertical distance between the tile's true surface (its bicubic patches
``control_points (n, 4, 4, 3)``) and that triangulation over the block:

* the surface is evaluated exactly on a lattice of ``samples`` points a patch side (patch corners
  and edges included, so every vertex of every stride's triangulation, and every point where a
  square stride cell's diagonal crosses the lattice), and the triangulation there exactly (the
  triangle each lattice point lies in, by the mesh's own diagonal rule);
* inside a lattice cell lying on one plane of the triangulation, the difference (surface minus
  that plane) is at most its largest corner value plus the bilinear interpolation error
  ``h**2 / 8 (|z_ss| + |z_tt|)`` (``h`` the lattice step in patch parameters; the second
  derivatives of the bicubic surface bounded on the cell: ``z_ss`` is linear in ``s``, so its
  largest corner value plus ``h**2 / 8 |z_sstt|``, from the control heights' fourth differences,
  or the whole patch's control-net bound ``6 max|second difference|`` if smaller);
* a lattice cell cut along its diagonal by a square stride cell's diagonal: each half lies in one
  plane, bounded by that plane extended over the cell (its distance at the four corners plus the
  same margin) or by the half cell's linear interpolation error ``h**2 / 4 (max(|z_ss|, |z_tt|) +
  |z_st|)`` over its three corners (circumradius ``h / sqrt 2``), whichever is smaller.

So the bound covers the whole fitted surface over the block for every square stride cell (all of
a tile whose patch count is a multiple of the stride: the 64-patch tiles of the benchmark worlds
but their last row and column of tiles).  In a tile's short trailing cells (``n`` patches not a
multiple of the stride) the diagonal crosses lattice cells off their corners: there the bound is
the lattice maximum plus the half-cell margin, which covers the surface where the cell's corners'
triangle is the one drawn and is second order in ``h`` elsewhere (not proven there).  Measured on
a rough synthetic world (hills 300 m high, 60 m patches): bound / densely sampled true distance
<= 1.26 at stride 1, 1.15 at 2 and 1.1 at 4 and 8.
"""

from __future__ import annotations

import numpy as np

from piste.terrain.bezier import bernstein

__all__ = ["block_stride_errors", "corner_stride_errors", "surface_lattice", "triangulated_at", "BLOCK_ERROR_SAMPLES"]

#: lattice points a patch side at which the surface is compared (the build's ``far_error`` uses 9)
BLOCK_ERROR_SAMPLES = 9


def _stride_index(n: int, stride: int) -> np.ndarray:
    i = np.arange(0, n, stride)
    return i if i[-1] == n - 1 else np.append(i, n - 1)


def surface_lattice(control_points: np.ndarray, grid_shape: tuple, samples: int = BLOCK_ERROR_SAMPLES
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fitted surface of a tile of ``grid_shape = (ny, nx)`` patches (``control_points (ny nx, 4,
    4, 3)``, patch ``row * nx + col``, ``[patch, a (x), b (y)]``) on ``samples`` points a patch
    side: ``z (ny samples, nx samples)`` float64 heights, ``gy (ny samples,)`` and ``gx (nx
    samples,)`` the lattice's coordinates in corner-grid units (patch row / column + fraction)."""
    ny, nx = grid_shape
    cp = np.asarray(control_points, dtype=np.float64)[..., 2].reshape(ny * nx, 4, 4)
    f = np.linspace(0.0, 1.0, samples)
    b = bernstein(f)  # (m, 4)
    z = b @ cp.transpose(0, 2, 1) @ b.T  # [patch, i (y), j (x)]: sum over a (x), b (y) of B_j(a) B_i(b) cp
    z = z.reshape(ny, nx, samples, samples).transpose(0, 2, 1, 3).reshape(ny * samples, nx * samples)
    gy = (np.arange(ny)[:, None] + f[None, :]).ravel()
    gx = (np.arange(nx)[:, None] + f[None, :]).ravel()
    return z, gy, gx


def triangulated_at(corner_z: np.ndarray, stride: int, gy: np.ndarray, gx: np.ndarray) -> np.ndarray:
    """The height of the stride-``stride`` triangulation of the corner heights ``corner_z (ny+1,
    nx+1)`` (as :func:`piste.render.streaming.far_mesh` draws it) at the lattice ``gy (R,)`` x
    ``gx (C,)`` (corner-grid units): ``(R, C)`` float64."""
    return _planes(corner_z, stride, gy, gx)[0]


def _planes(corner_z: np.ndarray, stride: int, gy: np.ndarray, gx: np.ndarray) -> tuple:
    """:func:`triangulated_at` and, at every lattice point, both planes of its stride cell (the
    triangle under ``fx >= fy`` and the other, extended over the cell) ``(R, C)``, each point's
    distance from the cell's diagonal along x ``(R, C)`` (corner-grid units; 0 on it) and whether
    its cell is square ``(R, C)`` bool."""
    z = np.asarray(corner_z, dtype=np.float64)
    ri, ci = _stride_index(z.shape[0], stride), _stride_index(z.shape[1], stride)
    jy = np.clip(np.searchsorted(ri, gy, side="right") - 1, 0, len(ri) - 2)
    jx = np.clip(np.searchsorted(ci, gx, side="right") - 1, 0, len(ci) - 2)
    fy = ((gy - ri[jy]) / (ri[jy + 1] - ri[jy]))[:, None]
    fx = ((gx - ci[jx]) / (ci[jx + 1] - ci[jx]))[None, :]
    zc = z[ri][:, ci]  # the stride's corners; each cell's plane coefficients, gathered row then column
    dx, dy = zc[:, 1:] - zc[:, :-1], zc[1:] - zc[:-1]

    def at(c: np.ndarray) -> np.ndarray:
        return c.take(jy, axis=0).take(jx, axis=1)

    z00 = at(zc[:-1, :-1])
    low = z00 + fx * at(dx[:-1]) + fy * at(dy[:, 1:])  # the triangle (r, c), (r, c+1), (r+1, c+1)
    up = z00 + fy * at(dy[:, :-1]) + fx * at(dx[1:])
    lower = fx >= fy
    wy, wx = (ri[jy + 1] - ri[jy])[:, None], (ci[jx + 1] - ci[jx])[None, :]
    return np.where(lower, low, up), low, up, (fx - fy) * wx, (wy == stride) & (wx == stride)


def _local_plane_margins(cz: np.ndarray, grid_shape: tuple, samples: int) -> np.ndarray:
    """Per patch ``(ny, nx)``: the bilinear interpolation error ``h**2 / 8 (|z_ss| + |z_tt|)`` with
    each lattice cell's own curvature: ``z_ss`` is linear in ``s`` and cubic in ``t``, so on a cell
    it is at most its largest value at the cell's corners plus ``h**2 / 8 max|z_sstt|`` (``<= 36
    max|second differences along s and t|`` of the control heights ``cz (n, 4, 4)``); likewise
    ``z_tt``.  The largest over the patch's cells."""
    ny, nx = grid_shape
    m = samples
    f = np.linspace(0.0, 1.0, m)
    b = bernstein(f)
    d2 = 6.0 * np.stack([1.0 - f, 3.0 * f - 2.0, 1.0 - 3.0 * f, f], -1)  # second derivatives of b (m, 4)
    h = 1.0 / (m - 1)
    four = np.abs(cz[:, 2:, 2:] - 2.0 * cz[:, 1:-1, 2:] + cz[:, :-2, 2:] - 2.0 * (cz[:, 2:, 1:-1] - 2.0 * cz[:, 1:-1, 1:-1]
                  + cz[:, :-2, 1:-1]) + cz[:, 2:, :-2] - 2.0 * cz[:, 1:-1, :-2] + cz[:, :-2, :-2]).max(axis=(1, 2))
    extra = h * h / 8.0 * 36.0 * four  # (n,)
    out = np.zeros(len(cz))
    for bs, bt in ((d2, b), (b, d2)):  # z_ss, then z_tt: [patch, i (t), j (s)]
        d = np.abs(bt @ cz.transpose(0, 2, 1) @ bs.T)  # [patch, i (t), j (s)]
        c = np.maximum(np.maximum(d[:, :-1, :-1], d[:, 1:, :-1]), np.maximum(d[:, :-1, 1:], d[:, 1:, 1:]))
        out = out + c.reshape(len(cz), -1).max(1) + extra  # (the sum of the maxima bounds the max of the sums)
    return (h * h / 8.0 * out).reshape(ny, nx)


def _patch_margins(control_points: np.ndarray, grid_shape: tuple, samples: int) -> tuple:
    """Per patch ``(ny, nx)``, for a cell on one plane and for a cell cut along its diagonal: how far
    the surface minus the triangulation can leave the largest of its lattice values inside a lattice cell (step ``h = 1 / (samples - 1)``), from the
    patch's control heights: ``|z_ss| <= 6 max|second difference along s|``, likewise ``t``,
    ``|z_st| <= 9 max|mixed difference|``.  A cell on one plane of the triangulation: the bilinear
    interpolation error ``h**2 / 8 (|z_ss| + |z_tt|)``; a cell cut along its diagonal by the
    triangulation's (patches on a square stride cell's diagonal, and every patch of a short
    trailing cell): the linear interpolation error on a half cell (circumradius ``h / sqrt 2``)
    ``h**2 / 4 (max(|z_ss|, |z_tt|) + |z_st|)``."""
    ny, nx = grid_shape
    cz = np.asarray(control_points, dtype=np.float64)[..., 2]  # (n, 4 (x: s), 4 (y: t))
    zss = 6.0 * np.abs(cz[:, 2:] - 2.0 * cz[:, 1:-1] + cz[:, :-2]).max(axis=(1, 2))
    ztt = 6.0 * np.abs(cz[:, :, 2:] - 2.0 * cz[:, :, 1:-1] + cz[:, :, :-2]).max(axis=(1, 2))
    zst = 9.0 * np.abs(cz[:, 1:, 1:] - cz[:, 1:, :-1] - cz[:, :-1, 1:] + cz[:, :-1, :-1]).max(axis=(1, 2))
    h = 1.0 / (samples - 1)
    plane = np.minimum((h * h / 8.0 * (zss + ztt)).reshape(ny, nx), _local_plane_margins(cz, grid_shape, samples))
    cut = (h * h / 4.0 * (np.maximum(zss, ztt) + zst)).reshape(ny, nx)
    return plane, np.maximum(cut, plane)


def _square_patches(grid_shape: tuple, stride: int) -> np.ndarray:
    """``(ny, nx)`` bool: the patches in square cells of the stride (not a tile's short trailing ones)."""
    ny, nx = grid_shape
    ri, ci = _stride_index(ny + 1, stride), _stride_index(nx + 1, stride)
    jy = np.searchsorted(ri, np.arange(ny), side="right") - 1  # each patch row's stride cell
    jx = np.searchsorted(ci, np.arange(nx), side="right") - 1
    return ((ri[jy + 1] - ri[jy]) == stride)[:, None] & ((ci[jx + 1] - ci[jx]) == stride)[None, :]


def _per_patch(a: np.ndarray, ny: int, nx: int, m: int) -> np.ndarray:
    """The largest of each patch's ``m x m`` lattice values ``a (ny m, nx m)``: ``(ny, nx)``."""
    return a.reshape(ny * m, nx, m).max(axis=2).reshape(ny, m, nx).max(axis=1)


def _reduce(a: np.ndarray, step: int, axis: int) -> np.ndarray:
    n = a.shape[axis]
    return np.maximum.reduceat(a, np.arange(0, n, step), axis=axis)


def block_stride_errors(control_points: np.ndarray, corner_z: np.ndarray, grid_shape: tuple, block: int,
                        strides: tuple, samples: int = BLOCK_ERROR_SAMPLES) -> np.ndarray:
    """For every block of ``block x block`` patches of a tile (``grid_shape (ny, nx)`` patches, its
    fitted ``control_points (ny nx, 4, 4, 3)`` and corner heights ``corner_z (ny+1, nx+1)``) and
    every stride of ``strides``: a bound on the largest vertical distance between the surface and
    the stride's triangulation over the block (module docstring), metres: ``(by bx, len(strides))``
    float64, block ``row * bx + col``."""
    ny, nx = grid_shape
    m = samples
    z, gy, gx = surface_lattice(control_points, grid_shape, m)
    plane0, cut = _patch_margins(control_points, grid_shape, m)
    out = []
    for k in strides:
        t, low, up, d, square = _planes(corner_z, k, gy, gx)
        e = np.abs(z - t)
        plane = np.where(_square_patches(grid_shape, k), plane0, cut)
        # a lattice cell cut along its diagonal by a square stride cell's: each half lies in one plane,
        # bounded either by that plane's distance at the cell's four corners (extended past the
        # diagonal) plus the bilinear margin, or by the distance at its three plus the half cell's
        # margin: the smaller of the two bounds, a patch
        near = square & (np.abs(d) <= 1.0 / (m - 1) + 1e-9)
        ext = _per_patch(np.where(near, np.maximum(np.abs(z - low), np.abs(z - up)), e), ny, nx, m)
        e = _per_patch(e, ny, nx, m)
        cut_patch = _per_patch(near, ny, nx, m)
        e = np.where(cut_patch, np.minimum(ext + plane, e + cut), e + plane)
        out.append(_reduce(_reduce(e, block, 0), block, 1).ravel())
    return np.stack(out, -1)


def corner_stride_errors(corner_z: np.ndarray, block: int, strides: tuple) -> np.ndarray:
    """For every block of ``block x block`` patches of a tile's corner heights ``corner_z (ny+1,
    nx+1)`` and every stride of ``strides``: the largest vertical distance between the full corner
    grid's triangulation (stride 1) and the stride's, over the block's corners (both border lines
    included), metres: ``(by bx, len(strides))`` float64.  Where the stride's cells are square (every
    cell but a tile's short trailing ones) the stride-1 triangulation refines the stride's (the
    diagonals run the same way), so the difference is linear on each stride-1 triangle and this is
    its exact maximum over the block; adding a bound on how far the surface leaves the stride-1
    triangulation (the build's ``far_error``) bounds the surface's distance by the triangle
    inequality (:class:`piste.render.streaming.TileCache`'s first errors, before the loader has
    measured :func:`block_stride_errors`)."""
    z = np.asarray(corner_z, dtype=np.float64)
    gy, gx = np.arange(z.shape[0], dtype=np.float64), np.arange(z.shape[1], dtype=np.float64)
    out = []
    for k in strides:
        e = np.abs(z - triangulated_at(z, k, gy, gx))
        for axis in (0, 1):  # blocks share their border lines: each block's last line is the next one's first
            n = e.shape[axis]
            s = np.arange(0, n - 1, block)
            last = np.take(e, np.minimum(s + block, n - 1), axis=axis)
            e = np.maximum(np.maximum.reduceat(e, s, axis=axis), last)
        out.append(e.ravel())
    return np.stack(out, -1)
