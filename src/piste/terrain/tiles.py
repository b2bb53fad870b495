"""Tiled patch nets: a net too large for memory, fitted and stored one tile at a time.

Layout
------
A height field ``z (H, W)`` with ``s`` sample intervals a patch side holds ``Px = (W - 1) // s`` by
``Py = (H - 1) // s`` patches (``edge="crop"``, as :func:`piste.terrain.fit.fit_heightfield`).  A
:class:`TileGrid` cuts them into tiles of ``T x T`` patches (the last row/column of tiles may be
smaller); tile ``(ty, tx)`` holds patches ``[tx T, min((tx+1) T, Px))`` in x and the same in y,
ordered ``row * width + col`` inside the tile (patch ``(0, 0)`` at the tile's south-west corner).

Fit with fixed shared boundaries (exact C0 across tiles)
--------------------------------------------------------
A global least-squares fit couples every control point of the world.  The tiled fit decouples it
in three stages, each a deterministic function of the samples it reads:

1. **Corners**: the control point at every tile corner is the height sample there.
2. **Tile edges**: each tile side is a 1-D C0 piecewise-cubic Bézier curve (``3m + 1`` control
   values for ``m`` patches) fitted by least squares to the samples along that side, with its two
   corner values fixed.  Both tiles that share a side compute it from the same samples with the same
   code, so they get the *same bits* (tested), and no tile waits for another.
3. **Interior**: the tile's ``(3 Ty + 1) x (3 Tx + 1)`` control grid with its boundary ring fixed
   from stage 2; the interior unknowns solve the separable least-squares problem
   ``min || Ay_I Z_I Ax_Iᵀ - (z - Ay Z_fixed Axᵀ) ||`` (normal equations along y then x).

x and y control points are the regular grid at thirds of a patch, computed from *global* indices,
so shared boundary control points are bit-identical in all three coordinates and the welded net of
any group of tiles is watertight.  The error is a little above the global fit (the edges see only
their own row of samples); measured on a 361 x 361 synthetic range: see ``tests/terrain/test_tiles.py``.

Storage
-------
A :class:`TileStore` is a folder: ``index.json`` (the grid, written atomically) and one ``.npz`` a
tile and product (``fit/t_0003_0012.npz``, ...), each written atomically and byte-deterministic
(fixed zip timestamps), carrying the key of its inputs so that a resumed build can check
(:meth:`TileStore.verify`) and skip it.  Nothing here ever holds more than a tile's neighbourhood.

Reading a world from a stranger
-------------------------------
A tiled world is validated like a bundle.  ``index.json`` is checked against a schema
(:func:`check_index`: known keys only, their types, a grid of at most :data:`MAX_TILES` tiles, tile
keys ``"ty,tx"`` inside the grid, finite bounds with ``lo <= hi``, patch counts that match the
grid); tile files are never named by the index (``<product>/t_YYYY_XXXX.npz`` is made from the
tile's numbers, a plain file name) and are opened through :mod:`piste.formats.safe_io` below the
world's folder (no symbolic link followed, FIFOs and devices refused before a read).  Every
``.npy`` header in a tile is read and checked (dtype, shape, the member's size, the shape the
grid expects) before its array is allocated.  A bad tile is a :class:`TileError` naming the
tile's file, the tile and the member (field).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, Any, cast

import numpy as np
import numpy.typing as npt

import math
import re

from piste.errors import FormatError, ValidationError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import anchor, loads_json, open_file, read_regular
from piste.terrain.bezier import bernstein
from piste.terrain.net import PatchNet

__all__ = ["TileGrid", "TileStore", "TileError", "check_index", "tile_entries", "fit_tile", "fit_edge", "tile_net",
           "neighbourhood_net", "npz_bytes", "TILES_FORMAT", "TILE_FIT_VERSION", "triangulated_heights",
           "read_tile_objects", "TILE_OBJECT_MEMBERS"]

TILES_FORMAT = "piste.TiledNet/1"
#: bumped whenever :func:`fit_tile`'s output for the same input changes
TILE_FIT_VERSION = "piste.tile-fit/1"
#: most tiles an index may describe (a hostile grid could claim 10^17; 10^6 tiles of 64 x 64
#: patches at 30 m a patch cover a continent)
MAX_TILES = 1_000_000
#: largest index.json read (a few hundred bytes a tile)
MAX_INDEX_BYTES = 1 << 30
#: largest array in a tile file (inflated)
MAX_TILE_MEMBER_BYTES = 1 << 30
#: largest tile file (compressed) and most members in one
MAX_TILE_FILE_BYTES = 1 << 31
MAX_TILE_MEMBERS = 64
#: largest absolute coordinate in an index's bounds, metres (the Earth's circumference is 4e7)
MAX_BOUND = 1e12
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


class TileError(FormatError):
    """A tile of a tiled world is bad (missing, torn, of the wrong shape, not finite, reached
    through a link): names the tile's file, the tile ``(ty, tx)`` and the member (``field``)."""

    def __init__(self, path: str | os.PathLike[str] | None, tile: Sequence[int] | None, message: str, field: str | None = None) -> None:
        self.tile = tuple(int(v) for v in tile) if tile is not None else None
        self.reason = message
        where = f"tile ({self.tile[0]}, {self.tile[1]}): " if self.tile is not None else ""
        super().__init__(path, where + message, field=field)

    def __reduce__(self) -> tuple[type[TileError], tuple[Any, ...]]:  # travels between processes intact
        return (TileError, (self.path, self.tile, self.reason, self.field))


# ----------------------------------------------------------------------------- the grid
@dataclass(frozen=True)
class TileGrid:
    """How a height field of ``samples = (H, W)`` is cut into tiles of ``tile_patches`` patches.

    Attributes
    ----------
    samples : (H, W) samples of the height field
    samples_per_patch : sample intervals a patch side (>= 3)
    tile_patches : patches a tile side
    spacing : (dx, dy) metres
    origin : (x, y) of sample ``[0, 0]``
    """

    samples: tuple
    samples_per_patch: int
    tile_patches: int
    spacing: tuple
    origin: tuple = (0.0, 0.0)

    def __post_init__(self) -> None:
        s, t = int(self.samples_per_patch), int(self.tile_patches)
        if s < 3:
            raise ValidationError(f"TileGrid: samples_per_patch must be >= 3, got {s}")
        if t < 1:
            raise ValidationError(f"TileGrid: tile_patches must be >= 1, got {t}")
        if self.patches[0] < 1 or self.patches[1] < 1 or self.patches[0] * self.patches[1] < 2:
            raise ValidationError(f"TileGrid: {self.samples[0]} x {self.samples[1]} samples hold fewer than 2 patches "
                                  f"of {s} sample intervals")
        if min(self.spacing) <= 0:
            raise ValidationError(f"TileGrid: spacing must be positive, got {self.spacing}")

    @property
    def patches(self) -> tuple[int, int]:
        """``(Py, Px)`` patches of the whole world."""
        s = self.samples_per_patch
        return (self.samples[0] - 1) // s, (self.samples[1] - 1) // s

    @property
    def shape(self) -> tuple[int, int]:
        """``(tiles_y, tiles_x)``."""
        t = self.tile_patches
        py, px = self.patches
        return -(-py // t), -(-px // t)

    @property
    def n_patches(self) -> int:
        return self.patches[0] * self.patches[1]

    def tiles(self) -> list[tuple[int, int]]:
        """Every ``(ty, tx)``, row by row."""
        return [(ty, tx) for ty in range(self.shape[0]) for tx in range(self.shape[1])]

    def patch_range(self, ty: int, tx: int) -> tuple[int, int, int, int]:
        """``(py0, py1, px0, px1)``: the tile's patches (half-open) in world patch indices."""
        if not (0 <= ty < self.shape[0] and 0 <= tx < self.shape[1]):
            raise ValidationError(f"TileGrid: no tile ({ty}, {tx}) in a grid of {self.shape[0]} x {self.shape[1]}")
        t = self.tile_patches
        py, px = self.patches
        return ty * t, min((ty + 1) * t, py), tx * t, min((tx + 1) * t, px)

    def sample_window(self, ty: int, tx: int) -> tuple[slice, slice]:
        """Rows and columns of the samples tile ``(ty, tx)`` covers (rims included)."""
        s = self.samples_per_patch
        y0, y1, x0, x1 = self.patch_range(ty, tx)
        return slice(y0 * s, y1 * s + 1), slice(x0 * s, x1 * s + 1)

    def tile_bounds_xy(self, ty: int, tx: int) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` metres of the tile."""
        s = self.samples_per_patch
        y0, y1, x0, x1 = self.patch_range(ty, tx)
        (dx, dy), (ox, oy) = self.spacing, self.origin
        return ox + x0 * s * dx, oy + y0 * s * dy, ox + x1 * s * dx, oy + y1 * s * dy

    def tile_of(self, x: float, y: float) -> tuple[int, int]:
        """The tile under world ``(x, y)`` (clamped to the grid)."""
        s, t = self.samples_per_patch, self.tile_patches
        (dx, dy), (ox, oy) = self.spacing, self.origin
        tx = int(np.floor((x - ox) / (s * dx * t)))
        ty = int(np.floor((y - oy) / (s * dy * t)))
        return min(max(ty, 0), self.shape[0] - 1), min(max(tx, 0), self.shape[1] - 1)

    def to_dict(self) -> dict:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict) -> "TileGrid":
        return cls(tuple(int(v) for v in d["samples"]), int(d["samples_per_patch"]), int(d["tile_patches"]),
                   tuple(float(v) for v in d["spacing"]), tuple(float(v) for v in d["origin"]))


# ----------------------------------------------------------------------------- the fit
def _basis(m: int, s: int) -> np.ndarray:
    """Dense ``(m s + 1, 3 m + 1)`` sample matrix of a C0 piecewise cubic of ``m`` segments."""
    k = np.arange(m * s + 1)
    seg = np.minimum(k // s, m - 1)
    w = bernstein(k / s - seg)  # (k, 4)
    a = np.zeros((len(k), 3 * m + 1))
    a[k[:, None], 3 * seg[:, None] + np.arange(4)] = w
    return a


def _spd_solve(g: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``g x = rhs`` for the banded SPD normal matrix of a C0 piecewise cubic (bandwidth 3:
    column ``3p`` meets ``3p - 3 .. 3p + 3``) with LAPACK's banded Cholesky: O(n), deterministic."""
    from scipy.linalg import solveh_banded

    n = len(g)
    u = min(3, n - 1)
    ab = np.zeros((u + 1, n))
    for k in range(u + 1):
        ab[u - k, k:] = np.diagonal(g, k)
    return solveh_banded(ab, rhs, check_finite=False)


def fit_edge(samples: npt.ArrayLike, s: int) -> np.ndarray:
    """Control values of a tile side: ``samples (m s + 1,)`` -> ``(3 m + 1,)`` float64.

    The end values are the end samples (shared with the neighbouring sides); the rest is the
    least-squares fit of the samples with those ends fixed.  A pure function of its arguments.
    """
    z = np.asarray(samples, dtype=np.float64)
    m = (len(z) - 1) // s
    out = np.empty(3 * m + 1)
    out[0], out[-1] = z[0], z[-1]
    a = _basis(m, s)
    rhs = z - a[:, 0] * z[0] - a[:, -1] * z[-1]
    ai = a[:, 1:-1]
    out[1:-1] = _spd_solve(ai.T @ ai, ai.T @ rhs)
    return out


def fit_tile_heights(window: npt.ArrayLike, s: int) -> np.ndarray:
    """The z control grid ``(3 Ty + 1, 3 Tx + 1)`` of a tile from its samples ``window
    (Ty s + 1, Tx s + 1)`` (rims included): corners, edges (:func:`fit_edge`), then the interior
    with the boundary fixed."""
    w = np.asarray(window, dtype=np.float64)
    ty, tx = (w.shape[0] - 1) // s, (w.shape[1] - 1) // s
    zc = np.zeros((3 * ty + 1, 3 * tx + 1))
    zc[0, :] = fit_edge(w[0, :], s)
    zc[-1, :] = fit_edge(w[-1, :], s)
    zc[:, 0] = fit_edge(w[:, 0], s)
    zc[:, -1] = fit_edge(w[:, -1], s)
    ay, ax = _basis(ty, s), _basis(tx, s)
    resid = w - ay @ zc @ ax.T  # what the fixed boundary leaves to the interior
    ayi, axi = ay[:, 1:-1], ax[:, 1:-1]
    if ayi.shape[1] and axi.shape[1]:
        rhs = ayi.T @ resid @ axi  # (Ny, Nx)
        tmp = _spd_solve(ayi.T @ ayi, rhs)  # Gy⁻¹ rhs
        zc[1:-1, 1:-1] = _spd_solve(axi.T @ axi, tmp.T).T  # ... Gx⁻¹
    return zc


def _axis_coords(first: int, count: int, step: float, origin: float) -> np.ndarray:
    """Coordinates of global control indices ``first .. first + count - 1`` (thirds of a patch)."""
    g = np.arange(first, first + count)
    return origin + (g // 3) * step + (g % 3) * (step / 3.0)


def tile_control_points(grid: TileGrid, ty: int, tx: int, zc: np.ndarray) -> np.ndarray:
    """``(n, 4, 4, 3)`` float64 control points of a tile from its z control grid."""
    s = grid.samples_per_patch
    py0, py1, px0, px1 = grid.patch_range(ty, tx)
    ny, nx = py1 - py0, px1 - px0
    (dx, dy), (ox, oy) = grid.spacing, grid.origin
    xs = _axis_coords(3 * px0, 3 * nx + 1, s * dx, ox)
    ys = _axis_coords(3 * py0, 3 * ny + 1, s * dy, oy)
    ii = 3 * np.arange(nx)[None, :, None, None] + np.arange(4)[None, None, :, None]
    jj = 3 * np.arange(ny)[:, None, None, None] + np.arange(4)[None, None, None, :]
    shape = (ny, nx, 4, 4)
    cp = np.empty(shape + (3,))
    cp[..., 0] = np.broadcast_to(xs[ii], shape)
    cp[..., 1] = np.broadcast_to(ys[jj], shape)
    cp[..., 2] = zc[jj, ii]
    return cp.reshape(ny * nx, 4, 4, 3)


def tile_uv(grid: TileGrid, cp: np.ndarray) -> np.ndarray:
    """Base-texture UV at the corners (one repeat a patch, from the world origin): ``(n, 4, 2)`` float32."""
    s = grid.samples_per_patch
    (dx, dy), (ox, oy) = grid.spacing, grid.origin
    corners = cp[:, [0, 3, 3, 0], [0, 0, 3, 3], :2]
    return np.stack([(corners[..., 0] - ox) / (s * dx), (corners[..., 1] - oy) / (s * dy)], -1).astype(np.float32)


def fit_tile(grid: TileGrid, ty: int, tx: int, window: npt.ArrayLike) -> dict[str, np.ndarray]:
    """Fit tile ``(ty, tx)`` from its sample window (:meth:`TileGrid.sample_window`).

    Returns ``{"control_points": (n, 4, 4, 3) float64, "uv": (n, 4, 2) float32}``.
    """
    w = np.asarray(window, dtype=np.float64)
    rows, cols = grid.sample_window(ty, tx)
    want = (rows.stop - rows.start, cols.stop - cols.start)
    if w.shape != want:
        raise ValidationError(f"tile ({ty}, {tx}): sample window of shape {w.shape}, expected {want}")
    bad = ~np.isfinite(w)
    if bad.any():
        r, c = (int(v) for v in np.argwhere(bad)[0])
        raise ValidationError(f"tile ({ty}, {tx}): non-finite height at row {rows.start + r}, column {cols.start + c}")
    zc = fit_tile_heights(w, grid.samples_per_patch)
    cp = tile_control_points(grid, ty, tx, zc)
    return {"control_points": cp, "uv": tile_uv(grid, cp)}


# ----------------------------------------------------------------------------- the index schema
#: index.json's keys and what each holds (piste.pipeline.tiled_build.write_index writes them all;
#: a world written by TileStore alone may hold only format and grid)
INDEX_KEYS = {"format": "a format name", "name": "a name", "grid": "the tile grid", "patches": "a patch count",
              "res": "light-map texels a patch side", "shadows": "true or false", "cell": "metres",
              "lights": "lights TOML text", "source": "the source's key", "tiles": "an object of tiles"}
TILE_KEYS = {"fit", "lit", "patches", "bounds"}
_TILE_KEY = re.compile(r"^(\d{1,7}),(\d{1,7})$")
_SHA = re.compile(r"^[0-9a-f]{64}$")


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_index(index: Any, path: str | os.PathLike[str]) -> dict[str, Any]:
    """``index`` (parsed ``index.json``) after checking every key it holds against the schema
    (:data:`INDEX_KEYS`): known keys only, of the right type and range.  The grid and the tiles
    are checked against each other by :meth:`TileStore.grid` and :func:`tile_entries`.
    FormatError naming ``path`` and the field."""

    def bad(field: str | None, message: str) -> FormatError:
        return FormatError(path, message, field=field)

    if not isinstance(index, dict):
        raise bad(None, f"expected an object with format {TILES_FORMAT!r}, got {type(index).__name__}")
    if index.get("format") != TILES_FORMAT:
        raise bad("format", f"expected format {TILES_FORMAT!r}, got {str(index.get('format'))[:60]!r}")
    for k in index:
        if k not in INDEX_KEYS:
            raise bad(k[:60], f"unknown key {k[:60]!r}: expected one of {', '.join(sorted(INDEX_KEYS))}")
    checks = {"name": lambda v: isinstance(v, str) and len(v) <= 4096, "grid": lambda v: isinstance(v, dict),
              "patches": lambda v: _is_int(v) and 0 <= v <= 10**12, "res": lambda v: _is_int(v) and 2 <= v <= 64,
              "shadows": lambda v: isinstance(v, bool), "cell": lambda v: _is_num(v) and 0 <= v <= 1e9,
              "lights": lambda v: isinstance(v, str) and len(v) <= 1 << 20,
              "source": lambda v: isinstance(v, str) and len(v) <= 4096, "tiles": lambda v: isinstance(v, dict)}
    for k, ok in checks.items():
        if k in index and not ok(index[k]):
            raise bad(k, f"expected {INDEX_KEYS[k]}" + (" (2..64)" if k == "res" else "") +
                      f", got {str(index[k])[:60]!r}")
    return index


def tile_entries(index: dict[str, Any], grid: TileGrid, path: str | os.PathLike[str]) -> dict[tuple[int, int], dict[str, Any]]:
    """The tiles ``index["tiles"]`` lists, checked: ``{(ty, tx): {"bounds": (2, 3) float64,
    "patches": int}}``.  Keys must be ``"ty,tx"`` of a tile of ``grid``, entries hold only
    :data:`TILE_KEYS`, ``patches`` equals the tile's patch count, ``bounds`` is
    ``[[x0, y0, z0], [x1, y1, z1]]`` of finite numbers with ``lo <= hi``.  FormatError naming
    ``path`` and the field (``tiles."0,0".bounds``)."""
    tiles = index.get("tiles")
    if not isinstance(tiles, dict) or not tiles:
        raise FormatError(path, "expected an object of tiles {\"ty,tx\": {...}}, got "
                                f"{str(tiles)[:60]!r}", field="tiles")
    out = {}
    for key, t in tiles.items():
        m = _TILE_KEY.match(key)
        field = f'tiles."{key[:40]}"'
        if not m:
            raise FormatError(path, f"expected a tile key \"ty,tx\" (two whole numbers), got {key[:40]!r}",
                              field=field)
        ty, tx = int(m.group(1)), int(m.group(2))
        if not (ty < grid.shape[0] and tx < grid.shape[1]):
            raise FormatError(path, f"no tile ({ty}, {tx}) in a grid of {grid.shape[0]} x {grid.shape[1]}", field=field)
        if not isinstance(t, dict):
            raise FormatError(path, f"expected an object, got {str(t)[:60]!r}", field=field)
        for k in t:
            if k not in TILE_KEYS:
                raise FormatError(path, f"unknown key {k[:40]!r}: expected {', '.join(sorted(TILE_KEYS))}",
                                  field=f"{field}.{k[:40]}")
        for k in ("fit", "lit"):
            if k in t and not (isinstance(t[k], str) and _SHA.match(t[k])):
                raise FormatError(path, f"expected a sha256 (64 hex digits), got {str(t[k])[:60]!r}", field=f"{field}.{k}")
        py0, py1, px0, px1 = grid.patch_range(ty, tx)
        n = (py1 - py0) * (px1 - px0)
        if t.get("patches") != n or not _is_int(t.get("patches")):
            raise FormatError(path, f"expected {n} patches (the grid's), got {str(t.get('patches'))[:60]!r}",
                              field=f"{field}.patches")
        b = t.get("bounds")
        ok = (isinstance(b, list) and len(b) == 2 and all(isinstance(r, list) and len(r) == 3 and
                                                          all(_is_num(v) and abs(v) <= MAX_BOUND for v in r) for r in b))
        if not ok or not isinstance(b, list) or not all(lo <= hi for lo, hi in zip(b[0], b[1])):
            raise FormatError(path, "expected [[x0, y0, z0], [x1, y1, z1]]: finite numbers (|v| <= 1e12) with "
                                    f"lo <= hi, got {str(b)[:80]}", field=f"{field}.bounds")
        out[(ty, tx)] = {"bounds": np.asarray(b, dtype=np.float64), "patches": n}
    return out


# ----------------------------------------------------------------------------- storage
def npz_bytes(arrays: dict) -> bytes:
    """A deterministic ``.npz`` (deflated, fixed timestamps, keys in the given order)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for name, arr in arrays.items():
            item = io.BytesIO()
            np.lib.format.write_array(item, np.asarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, item.getvalue(), compresslevel=1)
    return buf.getvalue()


class TileStore:
    """A tiled world on disk: ``root/index.json`` plus ``root/<product>/t_YYYY_XXXX.npz``.

    ``index.json`` holds ``{"format", "grid", "key", ...}``; products are ``fit`` (control points,
    UVs) and ``lit`` (light map, far field, visibility), each tile file carrying ``key`` (the hash of
    its inputs) so that :meth:`verify` can tell a finished tile from a stale or torn one.
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        # the folder the user named, as a confinement root: tiles are opened below it without
        # following links (piste.formats.safe_io)
        self.root = Path(anchor(root))

    # -- index
    @property
    def index_path(self) -> Path:
        return self.root / "index.json"

    def write_index(self, index: dict) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(self.index_path, (json.dumps(index, indent=1, sort_keys=True) + "\n").encode())

    def read_index(self) -> dict:
        if not self.index_path.exists():
            raise FormatError(self.index_path, "no such file: not a tiled world (run piste build first)")
        index = loads_json(read_regular(self.index_path, MAX_INDEX_BYTES), self.index_path)
        check_index(index, self.index_path)
        if index.get("tiles"):  # a built world: its tiles against its grid (keys, patch counts, bounds)
            tile_entries(index, self._grid_of(index), self.index_path)
        return index

    def grid(self) -> TileGrid:
        """The world's :class:`TileGrid` (FormatError naming ``index.json`` and the field)."""
        return self._grid_of(self.read_index())

    def _grid_of(self, index: dict) -> TileGrid:
        d = index.get("grid")
        if not isinstance(d, dict):
            raise FormatError(self.index_path, f"expected an object, got {type(d).__name__}", field="grid")
        fields = {"samples": (int, 2), "samples_per_patch": (int, 0), "tile_patches": (int, 0),
                  "spacing": (float, 2), "origin": (float, 2)}
        for name, (kind, length) in fields.items():
            v = d.get(name)
            items = v if length and isinstance(v, list) and len(v) == length else [v] if not length else None
            ok = items is not None and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) < 2**53  # (nan fails too)
                and (kind is float or float(x).is_integer()) for x in items)
            if not ok:
                want = f"{length} finite numbers" if length else "an integer"
                raise FormatError(self.index_path, f"expected {want}, got {str(v)[:60]}", field=f"grid.{name}")
        try:
            g = TileGrid.from_dict(d)
        except ValidationError as exc:
            raise FormatError(self.index_path, f"bad tile grid ({exc})", field="grid") from None
        if g.shape[0] * g.shape[1] > MAX_TILES:
            raise FormatError(self.index_path, f"a grid of {g.shape[0]} x {g.shape[1]} tiles: expected at most "
                                               f"{MAX_TILES:,}", field="grid")
        return g

    def read_fit(self, grid: TileGrid, ty: int, tx: int) -> dict:
        """A fitted tile's arrays, checked against the grid: ``{"control_points": (n, 4, 4, 3)
        float64, "uv": (n, 4, 2) float32}`` with ``n`` the tile's patches (TileError naming the
        tile and member when missing, of another shape, or not finite)."""
        py0, py1, px0, px1 = grid.patch_range(ty, tx)
        n = (py1 - py0) * (px1 - px0)
        a = self.read("fit", ty, tx, names=("control_points", "uv"),
                      expect={"control_points": ((n, 4, 4, 3), "fiu"), "uv": ((n, 4, 2), "fiu")})
        return {"control_points": a["control_points"].astype(np.float64, copy=False),
                "uv": a["uv"].astype(np.float32, copy=False)}

    # -- tiles
    def path(self, product: str, ty: int, tx: int) -> Path:
        return self.root / product / f"t_{ty:04d}_{tx:04d}.npz"

    def write(self, product: str, ty: int, tx: int, arrays: dict, key: str) -> str:
        """Write one tile atomically; returns the sha256 of its bytes."""
        data = npz_bytes({"key": np.array(key), **arrays})
        p = self.path(product, ty, tx)
        p.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(p, data)
        return hashlib.sha256(data).hexdigest()

    def read(self, product: str, ty: int, tx: int, key: str | None = None, names: Iterable[str] | None = None,
             expect: dict[str, tuple[tuple[int, ...], str]] | None = None) -> dict[str, np.ndarray]:
        """The arrays of one tile (all of them, or ``names``), each ``.npy`` header checked before
        its array is allocated (:func:`_read_npz`; ``expect``: ``{name: (shape, dtype kinds)}``).
        TileError naming the tile when missing, torn, stale, of the wrong shape or not finite."""
        p = self.path(product, ty, tx)
        want = None if names is None else tuple(names) + (("key",) if key is not None else ())
        arrays = _read_npz(p, (ty, tx), want, expect, product)
        got = str(arrays.pop("key", ""))
        if key is not None and got != key:
            raise TileError(p, (ty, tx), f"was built from other inputs (key {got[:12]}, expected {key[:12]})",
                            field="key")
        return arrays

    def verify(self, product: str, ty: int, tx: int, key: str) -> str | None:
        """sha256 of a finished tile whose key matches and whose arrays read back (CRC-checked), else None."""
        p = self.path(product, ty, tx)
        if not p.is_file():
            return None
        try:
            data = read_regular(p, MAX_TILE_FILE_BYTES, what="tile file")
            with zipfile.ZipFile(io.BytesIO(data)) as zf:
                if zf.testzip() is not None:
                    return None
                with zf.open("key.npy") as fh:
                    got = str(np.lib.format.read_array(fh, allow_pickle=False))
        except Exception:
            return None
        return hashlib.sha256(data).hexdigest() if got == key else None


def _header(p: Path, tile: tuple[int, int] | None, name: str, fh: IO[bytes],
            info: zipfile.ZipInfo) -> tuple[tuple[int, ...], bool, np.dtype[Any]]:
    """``(shape, fortran_order, dtype)`` of a member's ``.npy`` header, read from the stream (a
    few hundred bytes) and checked against the member's declared size before anything else."""
    try:
        version = np.lib.format.read_magic(fh)
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read(fh, max_header_size=10_000)
    except Exception as exc:
        raise TileError(p, tile, f"member {name!r} has an unreadable .npy header ({type(exc).__name__}: "
                                 f"{str(exc)[:100]})", field=name) from None
    if dtype.hasobject or dtype.fields is not None or dtype.kind not in "biufU" or dtype.itemsize == 0:
        raise TileError(p, tile, f"member {name!r} holds {dtype}, expected numbers", field=name)
    need = math.prod(shape) * dtype.itemsize  # Python ints: no overflow
    if need + fh.tell() != info.file_size:
        raise TileError(p, tile, f"member {name!r}: an array of shape {tuple(shape)} {dtype} needs {need:,} bytes, "
                                 f"the member holds {max(info.file_size - fh.tell(), 0):,}", field=name)
    return tuple(shape), fortran, dtype


def _read_npz(p: Path, tile: tuple[int, int] | None = None, names: Iterable[str] | None = None, expect: dict[str, tuple[tuple[int, ...], str]] | None = None,
              product: str = "tile") -> dict[str, np.ndarray]:
    """The arrays of tile file ``p`` (or only ``names``), opened through :mod:`piste.formats.safe_io`.

    Before a member's array is allocated: the member count, each member's declared size, its
    ``.npy`` header (numbers only; the shape times the item size equals the member's size) and,
    for members in ``expect`` (``{name: (shape, "fiu")}``), the shape and dtype kind; arrays in
    ``expect`` must be finite and within +-:data:`MAX_BOUND`.  Every failure is a TileError naming ``p``, the tile
    and the member."""
    tile = tile if tile is not None else (0, 0)
    try:
        fh = open_file(p, MAX_TILE_FILE_BYTES, what="tile file")
    except FormatError as exc:
        reason = getattr(exc, "reason", str(exc))
        if "No such file" in reason:
            reason = f"has no {product!r} output (no file {p.name})"
        raise TileError(p, tile, reason) from None
    out = {}
    with fh:
        try:
            zf = zipfile.ZipFile(fh)
        except Exception as exc:
            raise TileError(p, tile, f"not a readable tile (.npz: {type(exc).__name__}: {str(exc)[:100]})") from None
        with zf:
            infos = zf.infolist()
            if len(infos) > MAX_TILE_MEMBERS:
                raise TileError(p, tile, f"{len(infos)} members: more than {MAX_TILE_MEMBERS}")
            members = {}
            for info in infos:
                name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
                if name in members:
                    raise TileError(p, tile, f"member {name[:60]!r} appears twice", field=name[:60])
                members[name] = info
            for name in (names if names is not None else list(members)):
                if name not in members:
                    raise TileError(p, tile, f"has no {name}", field=name)
                info = members[name]
                if info.file_size > MAX_TILE_MEMBER_BYTES:
                    raise TileError(p, tile, f"member of {info.file_size:,} bytes: more than "
                                             f"{MAX_TILE_MEMBER_BYTES:,}", field=name)
                try:
                    with zf.open(info) as m:
                        shape, fortran, dtype = _header(p, tile, name, m, info)
                        if expect and name in expect:
                            want_shape, kinds = expect[name]
                            if shape != tuple(want_shape) or dtype.kind not in kinds:
                                raise TileError(p, tile, f"expected {tuple(want_shape)} numbers, got {shape} {dtype}",
                                                field=name)
                        arr = np.empty(shape, dtype, order="F" if fortran else "C")  # checked: at most the member
                        view = arr.reshape(-1, order="A").data.cast("B") if arr.size else memoryview(b"")
                        got = cast(io.BufferedIOBase, m).readinto(view) if arr.size else 0  # a ZipExtFile
                        if got != arr.nbytes:
                            raise TileError(p, tile, f"member {name!r} ended after {got} of {arr.nbytes} bytes",
                                            field=name)
                except TileError:
                    raise
                except Exception as exc:  # a bad CRC, a torn deflate stream
                    raise TileError(p, tile, f"member {name!r} is unreadable ({type(exc).__name__}: "
                                             f"{str(exc)[:100]})", field=name) from None
                if expect and name in expect and dtype.kind in "fiu" and arr.size:
                    if dtype.kind == "f" and not np.isfinite(arr).all():
                        raise TileError(p, tile, "holds non-finite values", field=name)
                    if dtype.itemsize > 1 and float(np.abs(arr).max()) > MAX_BOUND:  # would overflow float32 meshes
                        raise TileError(p, tile, f"holds values beyond +-{MAX_BOUND:g}", field=name)
                out[name] = arr
    return out


def triangulated_heights(z: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Heights of a triangulated per-patch grid ``z (n, m, m)`` (``[patch, j (v), i (u)]`` at
    parameters ``i / (m-1)``, each cell split along its (0, 0)-(1, 1) diagonal, as the streamed
    tile meshes are) at parameters ``t (k,)`` in both directions: ``(n, k, k)`` float64.  On a height
    field (x, y linear in u, v) this is the coarse mesh's surface above those points: the far
    levels' errors (the build's ``far_error``) and the streaming renderer's geomorph targets."""
    z = np.asarray(z, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    m = z.shape[1]
    c = np.minimum(np.floor(t * (m - 1)).astype(int), m - 2)
    f = t * (m - 1) - c
    ci, fu = c[None, :], f[None, :]  # u along the last axis
    cj, fv = c[:, None], f[:, None]
    z00, z10 = z[:, cj, ci], z[:, cj, ci + 1]
    z01, z11 = z[:, cj + 1, ci], z[:, cj + 1, ci + 1]
    lower = z00 + fu * (z10 - z00) + fv * (z11 - z10)  # fu >= fv: the triangle (00, 10, 11)
    upper = z00 + fv * (z01 - z00) + fu * (z11 - z01)  # the triangle (00, 11, 01)
    return np.where(fu >= fv, lower, upper)


#: the ``lit`` members holding a tile's scene objects (piste.pipeline.tile_objects): kind indices
#: ``(k,)`` integers and object -> world matrices ``(k, 4, 4)`` floats; both or neither
TILE_OBJECT_MEMBERS = ("objects_kind", "objects_matrix")
#: most objects a tile file may hold
MAX_TILE_OBJECTS = 1_000_000


def read_tile_objects(store: TileStore, grid: TileGrid, ty: int, tx: int, n_kinds: int) -> tuple[np.ndarray, np.ndarray]:
    """A tile's scene objects: ``kind (k,) int64`` in ``[0, n_kinds)`` and ``matrix (k, 4, 4)
    float64`` (finite, bottom row 0 0 0 1, the translation over the tile's bounds); empty arrays
    for a tile built without object rules.  TileError naming the file, the tile and the member when
    only one member is there, a header says another shape or type, or a value is out of range."""
    p = store.path("lit", ty, tx)
    names = _member_names(p, (ty, tx))
    have = [m for m in TILE_OBJECT_MEMBERS if m in names]
    if not have:
        return np.zeros(0, np.int64), np.zeros((0, 4, 4))
    if len(have) == 1:
        missing = next(m for m in TILE_OBJECT_MEMBERS if m not in have)
        raise TileError(p, (ty, tx), f"member {have[0]!r} without {missing!r}", field=missing)
    a = store.read("lit", ty, tx, names=TILE_OBJECT_MEMBERS)
    kind, mat = a["objects_kind"], a["objects_matrix"]

    def bad(name: str, msg: str) -> TileError:
        return TileError(p, (ty, tx), f"member {name!r}: {msg}", field=name)

    if kind.ndim != 1 or kind.dtype.kind not in "iu":
        raise bad("objects_kind", f"expected (k,) integers, got {kind.shape} {kind.dtype}")
    if len(kind) > MAX_TILE_OBJECTS:
        raise bad("objects_kind", f"{len(kind):,} objects: more than {MAX_TILE_OBJECTS:,}")
    if mat.shape != (len(kind), 4, 4) or mat.dtype.kind != "f":
        raise bad("objects_matrix", f"expected ({len(kind)}, 4, 4) floats, got {mat.shape} {mat.dtype}")
    if len(kind) and (int(kind.min()) < 0 or int(kind.max()) >= n_kinds):
        raise bad("objects_kind", f"expected kinds 0..{n_kinds - 1}, got {int(kind.min())}..{int(kind.max())}")
    mat = mat.astype(np.float64, copy=False)
    if not np.isfinite(mat).all() or np.abs(mat).max(initial=0.0) > MAX_BOUND:
        raise bad("objects_matrix", f"expected finite values within +-{MAX_BOUND:g}")
    if len(kind) and not (mat[:, 3] == np.array([0.0, 0.0, 0.0, 1.0])).all():
        raise bad("objects_matrix", "expected each matrix's bottom row to be 0 0 0 1")
    x0, y0, x1, y1 = grid.tile_bounds_xy(ty, tx)
    tol = 1e-6 * max(abs(x1 - x0), abs(y1 - y0), 1.0)
    t = mat[:, :2, 3]
    out = (t[:, 0] < x0 - tol) | (t[:, 0] > x1 + tol) | (t[:, 1] < y0 - tol) | (t[:, 1] > y1 + tol)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise bad("objects_matrix", f"object {i} stands at ({t[i, 0]:.6g}, {t[i, 1]:.6g}), outside the tile's "
                                    f"bounds x {x0:.6g}..{x1:.6g}, y {y0:.6g}..{y1:.6g}")
    return kind.astype(np.int64, copy=False), mat


def _member_names(p: Path, tile: tuple[int, int] | None) -> set[str]:
    """The member names (without ``.npy``) of tile file ``p`` (TileError when unreadable)."""
    try:
        with open_file(p, MAX_TILE_FILE_BYTES, what="tile file") as fh, zipfile.ZipFile(fh) as zf:
            return {n[:-4] if n.endswith(".npy") else n for n in zf.namelist()}
    except FormatError as exc:
        raise TileError(p, tile, getattr(exc, "reason", str(exc))) from None
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise TileError(p, tile, f"not a tile file ({type(exc).__name__}: {str(exc)[:100]})") from None


def tile_net(store: TileStore, ty: int, tx: int, name: str | None = None) -> PatchNet:
    """The :class:`PatchNet` of one fitted tile."""
    grid = store.grid()
    a = store.read_fit(grid, ty, tx)
    s = grid.samples_per_patch
    return PatchNet(a["control_points"], uv=a["uv"], tol=1e-6 * s * min(grid.spacing), name=name or f"tile {ty},{tx}")


def neighbourhood_net(store: TileStore, grid: TileGrid, ty: int, tx: int, halo: int = 1,
                      ring: int | None = None) -> tuple[PatchNet, np.ndarray]:
    """The net of tile ``(ty, tx)`` and its neighbours within ``halo`` tiles (welded: shared tile
    edges are bit-identical), and the index of each of the centre tile's patches in it, ``(n,)``.

    ``ring``: keep only neighbour patches within ``ring`` patches of the centre tile (None: all).
    """
    py0, py1, px0, px1 = grid.patch_range(ty, tx)
    cps, uvs, centre = [], [], None
    count = 0
    for y in range(max(ty - halo, 0), min(ty + halo + 1, grid.shape[0])):
        for x in range(max(tx - halo, 0), min(tx + halo + 1, grid.shape[1])):
            a = store.read_fit(grid, y, x)
            qy0, qy1, qx0, qx1 = grid.patch_range(y, x)
            gy, gx = np.mgrid[qy0:qy1, qx0:qx1]
            gy, gx = gy.ravel(), gx.ravel()
            keep = np.ones(len(gy), bool)
            if ring is not None:
                keep = (gy >= py0 - ring) & (gy < py1 + ring) & (gx >= px0 - ring) & (gx < px1 + ring)
            if (y, x) == (ty, tx):
                centre = count + np.arange(len(gy))
            cps.append(a["control_points"][keep])
            uvs.append(a["uv"][keep])
            count += int(keep.sum())
    s = grid.samples_per_patch
    net = PatchNet(np.concatenate(cps), uv=np.concatenate(uvs), tol=1e-6 * s * min(grid.spacing),
                   name=f"tile {ty},{tx} + {halo}")
    assert centre is not None  # the centre tile is always in the neighbourhood
    return net, centre
