"""Building a large world tile by tile: fit, bake (light maps, far field) and visibility per tile.

A tiled build never holds the whole net: each task reads the height samples of one tile (and, to
bake, the fitted tiles around it), writes its result atomically to a :class:`~piste.terrain.tiles.TileStore`,
and returns a few numbers.  Two passes:

1. ``fit``  (every tile, independent): :func:`piste.terrain.tiles.fit_tile` -> ``fit/t_Y_X.npz``
   (control points, UVs).  Shared tile edges are bit-identical by construction.
2. ``lit``  (every tile, after the fits of its 3 x 3 neighbourhood): light-map texels of the tile's
   patches (``(n, res, res, 3)`` uint8, half-bright), with normals averaged across tile seams and
   shadow rays against the neighbourhood (a halo of one tile, exact patches) and, beyond it, against
   the world's **far heights** (see below: a mountain several tiles away shadows this tile as far as the
   sun angle says), the **far field** (the tile's patch-corner grid with colours: a coarse
   stand-in the runtime draws for distant tiles), and per-cell **visibility** bitsets of the patches
   of the tile and its 3 x 3 neighbours seen from eyes over the tile
   (:func:`piste.pipeline.visibility.compute_visibility` with ``region`` the tile, horizon method,
   180 azimuths, cells of at least a quarter tile; the 3 x 3 tiles are the occluders, lowered to the
   lowest of the meshes the streaming renderer may draw for them: near, middle and corner grid,
   ``vis_meta`` ``levels``; ``vis_meta`` ``tiles`` lists the tiles in bit order: the renderer culls
   the near tiles around the eye's tile by them while those tiles are drawn at one of the levels;
   eyes are also sampled at the base height plus the steepest cell's ground rise, ``cover_ground``,
   with a set per sampled height, so eyes on steep ground keep sets), and,
   when the spec names object rules, the tile's **scene objects** (members ``objects_kind``,
   ``objects_matrix``: :func:`piste.pipeline.tile_objects.place_tile_objects`, placed by slope,
   altitude and density from per-cell hashes, so tiles agree whatever order or worker bakes them).

Between the two passes one task (:func:`far_heights_task`, after every fit) writes the world's
**far heights** ``far/t_0000_0000.npz``: the heights of the whole world's exact surface at
:data:`FAR_SUBDIV` + 1 points a patch side (30 m patches give 7.5 m cells; between nodes a crest
is lower by its chord error, about curvature x cell^2 / 8), max-pooled over blocks when that grid
would have more than :data:`FAR_MAX_CELLS` cells a side (an upper bound: distant ridges never lose
height), 32 MB at most.  Each bake marches its sun rays over it outside its 3 x 3 neighbourhood
(:func:`piste.lighting.shadows.far_field_occluded`).

Every task is a pure function of its inputs: the single-machine build (:func:`build_tiles`) and the
Dask build (:mod:`piste.pipeline.dask_build`) run the same tasks and write the same bytes.  A task's
numeric work runs with the BLAS / OpenMP pools pinned to one thread
(:func:`piste.terrain.heightfield.single_threaded`): a multi-threaded OpenBLAS sums blocks of a
product in an order that depends on its thread count, which made a local build differ from a
single-threaded Dask worker's in the last bits of ~1 % of the fitted control points.  A task
whose output file exists and verifies (its stored key equals the key of its inputs, its zip CRCs
check) is skipped, so a killed build resumes where it stopped.  ``index.json`` is written last.

Height sources
--------------
:class:`ArraySource` (an array in memory), :class:`FileSource` (a scene's height field: a GeoTIFF
read window by window, decoding only the tiles/strips under each tile; PNG or .npz read once per
process) and :class:`SyntheticSource` (a seeded fractal range computed
from global sample indices with + - * only, so any window of it has the same bits; no file at all).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.errors import ConfigError, FormatError, PisteError, ValidationError
from piste.formats.geotiff import open_geotiff_windows
from piste.formats.safe_io import open_file
from piste.lighting.lightmap import encode_half_bright, sample_points, weld_seam_light
from piste.lighting.lights import default_lights, dumps_lights, light_terms, loads_lights, shade
from piste.lighting.lights import DirectionalLight
from piste.lighting.shadows import far_field_occluded, ray_offset, shadow_rays, shadow_visibility
from piste.pipeline.build import scene_lights
from piste.pipeline.cache import content_key
from piste.pipeline.sources import load_heightfield
from piste.pipeline.tile_objects import ObjectRule, place_tile_objects, rules_key
from piste.pipeline.visibility import compute_visibility
from piste.render.streaming import MID_SAMPLES, NEAR_SAMPLES
from piste.terrain.bezier import evaluate, grid_params
from piste.terrain.heightfield import single_threaded
from piste.terrain.tiles import (TILE_FIT_VERSION, TILES_FORMAT, TileGrid, TileStore, fit_tile, neighbourhood_net,
                                 triangulated_heights)
from piste.terrain.tiles import TileError as TileFileError

if TYPE_CHECKING:
    from piste.lighting.lights import Lights
    from piste.world.scene_file import SceneFile, TerrainSpec

__all__ = ["TiledSpec", "TiledResult", "ArraySource", "FileSource", "SyntheticSource", "TileError", "fit_task",
           "lit_task",
           "spec_from_scene", "synthetic_spec",
           "build_tiles", "write_index", "TILE_BAKE_VERSION", "far_errors", "far_heights_task", "FAR_HEIGHTS_VERSION",
           "FAR_MAX_CELLS", "FAR_SUBDIV"]

#: bumped whenever :func:`lit_task`'s output for the same input changes
TILE_BAKE_VERSION = "piste.tile-bake/5"  # 2: seam light welded (as the one-bundle bake: weld_seam_light); 3: far_error
# 4: far-field shadows (sun rays beyond the 3 x 3 neighbourhood marched over the world's far heights);
#    scene objects placed by rules (objects_kind, objects_matrix) when the spec has object rules
# 5: visibility sets over the 3 x 3 tiles' patches (vis_meta "tiles"), seen from eyes over the tile, the
#    occluders lowered to the drawn meshes (vis_meta "levels"), eye heights covering steep cells
#: bumped whenever :func:`far_heights_task`'s output for the same fits changes
FAR_HEIGHTS_VERSION = "piste.far-heights/1"
#: most cells a side of the far heights grid (more: max-pooled in blocks)
FAR_MAX_CELLS = 2048
#: far heights cells a patch side (the surface evaluated at FAR_SUBDIV + 1 points a patch side)
FAR_SUBDIV = 4


class TileError(TileFileError):
    """A tile task failed: names the tile and the step (a :class:`piste.terrain.tiles.TileError`,
    so one ``except`` catches a bad tile whether a build or a reader found it)."""

    def __init__(self, step: str, ty: int, tx: int, cause):
        self.step, self.tile, self.cause = step, (ty, tx), str(cause)
        what = cause if isinstance(cause, str) else f"{type(cause).__name__}: {cause}"
        self.path, self.line, self.field = getattr(cause, "path", None), None, getattr(cause, "field", None)
        self.reason = what
        PisteError.__init__(self, f"tile ({ty}, {tx}) failed in step {step!r}: {what}")

    def __reduce__(self):  # travels back from Dask workers intact
        msg = str(self).split(": ", 1)[1] if ": " in str(self) else str(self)
        return (TileError, (self.step, self.tile[0], self.tile[1], msg))


# ----------------------------------------------------------------------------- height sources
@dataclass(frozen=True)
class ArraySource:
    """Heights from an array in memory (or a ``np.memmap``), ``(H, W)`` metres."""

    z: np.ndarray = field(repr=False)
    spacing: tuple = (1.0, 1.0)
    key: str = ""

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.z.shape)

    def window(self, rows: slice, cols: slice) -> np.ndarray:
        return np.asarray(self.z[rows, cols], dtype=np.float64)

    def source_key(self) -> str:
        return self.key or content_key("array", np.ascontiguousarray(self.z))


_FILE_CACHE: dict = {}
_WINDOWS_CACHE: dict = {}


@dataclass(frozen=True)
class FileSource:
    """A scene's height field (a :class:`~piste.world.scene_file.TerrainSpec` of kind geotiff,
    heightfield).

    A GeoTIFF is read window by window (:class:`~piste.formats.geotiff.GeoTiffWindows`: only the
    tiles or strips under a tile's samples are decoded, so a task's memory does not grow with the
    DEM: a 20,000 x 20,000 DEM is fitted tile by tile), with the bits a whole read would give.
    The whole field is read once per process (kept as float32 when that loses nothing: a
    10,000 x 10,000 DEM holds 400 MB a process) for a PNG or .npz height field, and for a GeoTIFF
    window that holds missing samples when the fill is ``"nearest"`` (the nearest valid sample may
    lie in another tile; a numeric fill stays windowed)."""

    spec: TerrainSpec = field(repr=False)

    def _stat_key(self) -> tuple:
        p = Path(self.spec.path)
        st = p.stat()
        return (str(p), st.st_mtime_ns, st.st_size, self.spec.vertical_units)

    def _windows(self):
        """The GeoTIFF's :class:`~piste.formats.geotiff.GeoTiffWindows` (the file held open, its header and
        segment table read once per process), None for other files."""
        if self.spec.kind != "geotiff":
            return None
        k = self._stat_key()
        if k not in _WINDOWS_CACHE:
            for old in _WINDOWS_CACHE.values():  # one DEM at a time per process
                old.close()
            _WINDOWS_CACHE.clear()
            _WINDOWS_CACHE[k] = open_geotiff_windows(self.spec.path, vertical_units=self.spec.vertical_units)
        return _WINDOWS_CACHE[k]

    def _load(self):
        k = self._stat_key() + (self.spec.height_scale, self.spec.height_offset, str(self.spec.nodata),
                                self.spec.key, self.spec.spacing)
        if k not in _FILE_CACHE:
            _FILE_CACHE.clear()  # one DEM at a time per process
            z, spacing = load_heightfield(self.spec)
            z32 = z.astype(np.float32)
            if np.array_equal(z32, z):  # e.g. a float32 GeoTIFF in metres: half the memory, the same values
                z = z32
            _FILE_CACHE[k] = (z, spacing)
        return _FILE_CACHE[k]

    @property
    def shape(self) -> tuple[int, int]:
        w = self._windows()
        return tuple(w.shape) if w is not None else tuple(self._load()[0].shape)

    @property
    def spacing(self) -> tuple:
        w = self._windows()
        if w is None:
            return tuple(self._load()[1])
        return tuple(float(v) for v in (self.spec.spacing or w.spacing))  # as load_heightfield chooses

    def window(self, rows: slice, cols: slice) -> np.ndarray:
        """Heights ``(len(rows), len(cols))`` float64 metres (scale and offset applied)."""
        w = self._windows()
        if w is not None:
            z, mask = w.read(rows, cols)
            fill = self.spec.nodata
            if mask.any() and not isinstance(fill, str):  # a numeric fill needs no other window
                z[mask] = float(fill)
                mask = mask & False
            if not mask.any():
                out = z * self.spec.height_scale + self.spec.height_offset  # load_heightfield's arithmetic
                if not np.isfinite(out).all():
                    raise FormatError(w.path, f"height field has {int(np.count_nonzero(~np.isfinite(out)))} "
                                              "non-finite samples after height_scale and height_offset")
                return out
        return np.asarray(self._load()[0][rows, cols], dtype=np.float64)

    def source_key(self) -> str:
        import hashlib

        with open_file(Path(self.spec.path), what="height field") as fh:  # streamed: the DEM may not fit in memory
            h = hashlib.file_digest(fh, "sha256").hexdigest()
        s = self.spec
        return content_key("file", h, s.kind, s.height_scale, s.height_offset, str(s.nodata), s.vertical_units, s.key,
                           s.spacing)


def _hash2(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """Lattice values in [0, 1) from integer coordinates (a 64-bit integer hash)."""
    h = (ix.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)) ^ (iy.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F))
    h ^= np.uint64(seed * 0x165667B19E3779F9 & 0xFFFFFFFFFFFFFFFF)
    h ^= h >> np.uint64(31)
    h *= np.uint64(0x94D049BB133111EB)
    h ^= h >> np.uint64(29)
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


@dataclass(frozen=True)
class SyntheticSource:
    """A seeded fractal mountain range of ``shape = (H, W)`` samples at ``spacing`` metres.

    Ridged value noise (6 octaves) with smoothstep interpolation, computed from global sample
    indices with integer hashing and ``+ - *`` only: every window has exactly the bits the whole
    field would have, on any machine.  Heights ~0 .. ``relief`` metres.
    """

    shape: tuple = (3001, 3001)
    spacing: tuple = (10.0, 10.0)
    seed: int = 0
    relief: float = 1500.0
    wavelength: float = 2400.0

    def window(self, rows: slice, cols: slice) -> np.ndarray:
        r = np.arange(rows.start, min(rows.stop, self.shape[0]), dtype=np.int64)
        c = np.arange(cols.start, min(cols.stop, self.shape[1]), dtype=np.int64)
        out = np.zeros((len(r), len(c)))
        amp, total = 1.0, 0.0
        for octave in range(6):
            # lattice cell size in samples (an integer: exact cell/fraction arithmetic)
            cy = max(int(round(self.wavelength / self.spacing[1] / 2**octave)), 2)
            cx = max(int(round(self.wavelength / self.spacing[0] / 2**octave)), 2)
            iy, fy = r // cy, (r % cy).astype(np.float64) * (1.0 / cy)
            ix, fx = c // cx, (c % cx).astype(np.float64) * (1.0 / cx)
            sy, sx = fy * fy * (3.0 - 2.0 * fy), fx * fx * (3.0 - 2.0 * fx)
            s = self.seed * 7 + octave
            v00 = _hash2(ix[None, :], iy[:, None], s)
            v10 = _hash2(ix[None, :] + 1, iy[:, None], s)
            v01 = _hash2(ix[None, :], iy[:, None] + 1, s)
            v11 = _hash2(ix[None, :] + 1, iy[:, None] + 1, s)
            a = v00 + (v10 - v00) * sx[None, :]
            b = v01 + (v11 - v01) * sx[None, :]
            n = a + (b - a) * sy[:, None]
            ridge = 1.0 - (2.0 * n - 1.0) * (2.0 * n - 1.0) if octave else n
            out += amp * ridge
            total += amp
            amp *= 0.5
        return out * (self.relief / total)

    def source_key(self) -> str:
        return content_key("synthetic/1", list(self.shape), list(self.spacing), self.seed, self.relief, self.wavelength)


# ----------------------------------------------------------------------------- the spec
@dataclass
class TiledSpec:
    """Everything a tile task needs (picklable: it travels to Dask workers).

    Attributes
    ----------
    root : the tile store folder
    source : ArraySource | FileSource | SyntheticSource
    grid : TileGrid
    lights_toml : the lights as :func:`piste.lighting.lights.dumps_lights` text ("": the default lights)
    res, shadows : light-map texels a patch side, terrain self-shadowing
    cell, eye_heights : visibility cells (metres) and eye heights; ``cell = 0`` skips visibility
    far_shadows : with ``shadows``, sun rays leaving the 3 x 3 neighbourhood are tested against the
        world's far heights (False: occluders within one tile only, as before)
    objects, object_seed : :class:`~piste.pipeline.tile_objects.ObjectRule` s placing scene objects
        on every tile (``()``: none) and their seed
    """

    root: str
    source: object = field(repr=False)
    grid: TileGrid = None
    lights_toml: str = ""
    res: int = 4
    shadows: bool = True
    cell: float = 0.0
    eye_heights: tuple = (1.7, 9.0)
    name: str = "world"
    far_shadows: bool = True
    objects: tuple = ()
    object_seed: int = 0
    _src_key: str = field(default="", repr=False)

    @property
    def store(self) -> TileStore:
        return TileStore(self.root)

    def source_key(self) -> str:
        if not self._src_key:
            self._src_key = self.source.source_key()
        return self._src_key

    def fit_key(self, ty: int, tx: int) -> str:
        return content_key(TILE_FIT_VERSION, self.source_key(), self.grid.to_dict(), ty, tx)

    def lit_key(self, ty: int, tx: int) -> str:
        g = self.grid
        near = [self.fit_key(y, x) for y in range(max(ty - 1, 0), min(ty + 2, g.shape[0]))
                for x in range(max(tx - 1, 0), min(tx + 2, g.shape[1]))]
        far = self.far_key() if self.uses_far_heights else ""
        return content_key(TILE_BAKE_VERSION, near, self.lights_toml, self.res, self.shadows, self.cell,
                           list(self.eye_heights), far, rules_key(self.objects), int(self.object_seed))

    @property
    def uses_far_heights(self) -> bool:
        """True when the bake tests sun rays against the far heights (shadows on, and some tile lies
        outside some tile's 3 x 3 neighbourhood)."""
        return bool(self.shadows and self.far_shadows and max(self.grid.shape) > 2)

    def far_key(self) -> str:
        """The key of the far heights (a function of every fit: of the source and the grid)."""
        return content_key(FAR_HEIGHTS_VERSION, TILE_FIT_VERSION, self.source_key(), self.grid.to_dict(), FAR_MAX_CELLS,
                           FAR_SUBDIV)

    def lights(self) -> Lights:
        return loads_lights(self.lights_toml, "<lights>") if self.lights_toml else _default_lights()


def _default_lights():
    return default_lights()


# ----------------------------------------------------------------------------- tasks
def fit_task(spec: TiledSpec, ty: int, tx: int) -> dict:
    """Fit one tile (skipped when its output verifies): ``{"tile", "sha256", "skipped", "seconds"}``."""
    t0 = time.perf_counter()
    key = spec.fit_key(ty, tx)
    store = spec.store
    sha = store.verify("fit", ty, tx, key)
    if sha is not None:
        return {"tile": (ty, tx), "sha256": sha, "skipped": True, "seconds": 0.0}
    try:
        rows, cols = spec.grid.sample_window(ty, tx)
        window = spec.source.window(rows, cols)
        with single_threaded():  # one BLAS thread: the same bits locally and on any Dask worker
            arrays = fit_tile(spec.grid, ty, tx, window)
        sha = store.write("fit", ty, tx, arrays, key)
    except Exception as exc:
        raise TileError("fit", ty, tx, exc) from exc
    return {"tile": (ty, tx), "sha256": sha, "skipped": False, "seconds": time.perf_counter() - t0}


def _corner_grid(cp: np.ndarray) -> np.ndarray:
    """The patch-corner grid ``(ny + 1, nx + 1, 3)`` of a tile's control points ``(ny, nx, 4, 4, 3)``
    (rows along y, columns along x: exact surface points)."""
    ny, nx = cp.shape[:2]
    far = np.empty((ny + 1, nx + 1, 3))
    far[:-1, :-1] = cp[:, :, 0, 0]
    far[:-1, -1] = cp[:, -1, 3, 0]
    far[-1, :-1] = cp[-1, :, 0, 3]
    far[-1, -1] = cp[-1, -1, 3, 3]
    return far


def far_heights(spec: TiledSpec) -> dict:
    """The world's far heights from its fits: ``{"heights": (ny, nx) float64 metres, "frame": (4,)
    float64 (x, y of node [0, 0], node spacing x, y)}``.  The surface at ``FAR_SUBDIV + 1`` points
    a patch side (exact: the patches evaluated), then nodes every ``stride`` of those (``stride =
    ceil(cells a side / FAR_MAX_CELLS)``); with ``stride > 1`` a node holds the highest point
    within half a stride of it."""
    g = spec.grid
    k = FAR_SUBDIV
    u, v = grid_params(k + 1)
    py, px = (n * k for n in g.patches)  # cells a side
    stride = max(1, -(-max(py, px) // FAR_MAX_CELLS))
    half = stride // 2
    ny, nx = -(-py // stride) + 1, -(-px // stride) + 1
    heights = np.full((ny, nx), -np.inf)
    store = spec.store

    def nodes(c: np.ndarray, last: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The nodes within half a stride of fine indices ``c`` (the last fine index also feeds
        the nodes beyond it, as an edge-padded grid would): lowest and highest node index."""
        lo = np.maximum(-((half - c) // stride), 0)
        hi = np.where(c == last, n - 1, np.minimum((c + half) // stride, n - 1))
        return lo, hi

    for ty, tx in g.tiles():  # one tile's surface in memory at a time: never the whole fine grid
        y0, y1, x0, x1 = g.patch_range(ty, tx)
        cp = store.read_fit(g, ty, tx)["control_points"]
        z = evaluate(cp, u, v, normals=False)[..., 2].reshape(y1 - y0, x1 - x0, k + 1, k + 1)  # [py, px, j (v), i (u)]
        fine = _subdiv_grid(z, k)
        if stride == 1:
            heights[y0 * k:y1 * k + 1, x0 * k:x1 * k + 1] = fine
            continue
        rl, rh = nodes(np.arange(y0 * k, y1 * k + 1), py, ny)
        cl, ch = nodes(np.arange(x0 * k, x1 * k + 1), px, nx)
        for a in range(3):  # a fine point feeds at most 3 nodes a side (2, and the edge's padding)
            rsel = np.flatnonzero(rl + a <= rh)
            for b in range(3):
                csel = np.flatnonzero(cl + b <= ch)
                if len(rsel) and len(csel):
                    np.maximum.at(heights, ((rl + a)[rsel][:, None], (cl + b)[csel][None, :]),
                                  fine[np.ix_(rsel, csel)])
    s = g.samples_per_patch * stride / k
    (dx, dy), (ox, oy) = g.spacing, g.origin
    return {"heights": heights, "frame": np.array([ox, oy, s * dx, s * dy], dtype=np.float64)}


def _subdiv_grid(z: np.ndarray, k: int) -> np.ndarray:
    """One tile's surface heights ``z (ny, nx, k + 1, k + 1)`` (``[patch row, patch column, j (v),
    i (u)]``) as a grid ``(ny * k + 1, nx * k + 1)`` (rows along y; shared patch edges from the
    lower patch, as the fits weld them bit-identically anyway)."""
    ny, nx = z.shape[:2]
    out = np.empty((ny * k + 1, nx * k + 1))
    out[:-1, :-1] = z[:, :, :k, :k].transpose(0, 2, 1, 3).reshape(ny * k, nx * k)
    out[:-1, -1] = z[:, -1, :k, k].reshape(ny * k)
    out[-1, :-1] = z[-1, :, k, :k].reshape(nx * k)
    out[-1, -1] = z[-1, -1, k, k]
    return out


def far_heights_task(spec: TiledSpec, *_deps: Any) -> dict:
    """Write the world's far heights (after every fit; skipped when its output verifies or no bake
    needs it): ``{"sha256", "skipped", "seconds"}``.  ``_deps`` only orders the task after the fits."""
    t0 = time.perf_counter()
    if not spec.uses_far_heights:
        return {"sha256": "", "skipped": True, "seconds": 0.0}
    key = spec.far_key()
    store = spec.store
    sha = store.verify("far", 0, 0, key)
    if sha is not None:
        return {"sha256": sha, "skipped": True, "seconds": 0.0}
    try:
        with single_threaded():  # one BLAS thread: the same bits locally and on any Dask worker
            arrays = far_heights(spec)
        sha = store.write("far", 0, 0, arrays, key)
    except Exception as exc:
        raise TileError("far heights", 0, 0, exc) from exc
    return {"sha256": sha, "skipped": False, "seconds": time.perf_counter() - t0}


_FAR_CACHE: dict = {}


def _read_far_heights(spec: TiledSpec) -> dict:
    """The far heights written by :func:`far_heights_task` (read once per process and key)."""
    key = spec.far_key()
    root = str(spec.store.root)
    if (root, key) not in _FAR_CACHE:
        a = spec.store.read("far", 0, 0, key=key, names=("heights", "frame"), expect={"frame": ((4,), "f")})
        h = a["heights"]
        if h.ndim != 2 or min(h.shape) < 2 or not np.isfinite(h).all():
            raise TileFileError(spec.store.path("far", 0, 0), (0, 0), f"member 'heights': expected a finite "
                                f"(ny, nx) grid of at least 2 x 2, got shape {h.shape}", field="heights")
        _FAR_CACHE.clear()  # one world at a time per process
        _FAR_CACHE[(root, key)] = {"heights": h.astype(np.float64), "frame": a["frame"].astype(np.float64)}
    return _FAR_CACHE[(root, key)]


def _far_shadows(spec: TiledSpec, ty: int, tx: int, lights, pos, nrm, terms, shadow, eps: float, stats: dict) -> None:
    """Zero ``shadow (k, m)`` where a directional light's ray, lit by the neighbourhood's exact
    test, passes below the far heights beyond the 3 x 3 neighbourhood."""
    far = _read_far_heights(spec)
    g = spec.grid
    fx0, fy0, cx, cy = (float(v) for v in far["frame"])
    y0, x0 = max(ty - 1, 0), max(tx - 1, 0)
    y1, x1 = min(ty + 1, g.shape[0] - 1), min(tx + 1, g.shape[1] - 1)
    box = (g.tile_bounds_xy(y0, x0)[0], g.tile_bounds_xy(y0, x0)[1], g.tile_bounds_xy(y1, x1)[2],
           g.tile_bounds_xy(y1, x1)[3])
    for col, light in enumerate(lights.direct):
        if not (light.shadows and light.intensity != 0.0 and isinstance(light, DirectionalLight)):
            continue  # point and spot lights: occluders within the neighbourhood only
        idx = np.flatnonzero((terms[:, col] > 0.0) & (shadow[:, col] > 0.0))
        if len(idx) == 0:
            continue
        o, d, _ = shadow_rays(light, pos[idx], nrm[idx], eps)
        occ = far_field_occluded(far["heights"], (fx0, fy0), (cx, cy), o, d, box)
        shadow[idx[occ], col] = 0.0
        stats["far_rays"] = stats.get("far_rays", 0) + len(idx)
        stats["far_occluded"] = stats.get("far_occluded", 0) + int(occ.sum())


def lit_task(spec: TiledSpec, ty: int, tx: int, *_deps: Any) -> dict:
    """Bake one tile's light map, far field and visibility (needs the fits of its neighbourhood).

    Returns ``{"tile", "sha256", "skipped", "seconds", "samples", "rays", "zmin", "zmax", "patches"}``.
    ``_deps`` only orders the task after its neighbours' fits (Dask futures).
    """
    t0 = time.perf_counter()
    key = spec.lit_key(ty, tx)
    store = spec.store
    sha = store.verify("lit", ty, tx, key)
    if sha is not None:
        meta = store.read("lit", ty, tx)["meta"]
        return {"tile": (ty, tx), "sha256": sha, "skipped": True, "seconds": 0.0, "samples": 0, "rays": 0, "far_rays": 0,
                "zmin": float(meta[0]), "zmax": float(meta[1]), "patches": int(meta[2])}
    try:
        with single_threaded():  # one BLAS thread: the same bits locally and on any Dask worker
            arrays, info = _bake_tile(spec, ty, tx)
        sha = store.write("lit", ty, tx, arrays, key)
    except Exception as exc:
        raise TileError("lit", ty, tx, exc) from exc
    return {"tile": (ty, tx), "sha256": sha, "skipped": False, "seconds": time.perf_counter() - t0, **info}


def _bake_tile(spec: TiledSpec, ty: int, tx: int, halo: int = 1) -> tuple[dict, dict]:
    """The arrays of tile ``(ty, tx)``'s ``lit`` file and the task's numbers.  ``halo``: the tiles
    around it whose exact patches are the occluders (1 in a build; a whole world's halo with
    ``spec.far_shadows`` off is the non-tiled reference bake the tests compare against)."""
    g, res = spec.grid, spec.res
    store = spec.store
    lights = spec.lights()
    # seam-averaged sample points: the tile plus a ring of one patch of its neighbours, all lit, so
    # that the seams' light is welded like the one-bundle bake's (weld_seam_light: both patches of
    # an edge, the tile's border included, hold the mean of their two sides)
    ring_net, centre = neighbourhood_net(store, g, ty, tx, halo=1, ring=1)
    pos, nrm = sample_points(ring_net, res)
    m = len(ring_net)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    n = len(centre)
    stats: dict = {}
    shadow = None
    if spec.shadows and any(light.shadows for light in lights.direct):
        occluders, _ = neighbourhood_net(store, g, ty, tx, halo=halo)
        terms = light_terms(lights, pos, nrm)
        shadow = shadow_visibility(occluders, lights, pos, nrm, terms, stats=stats)
        if spec.uses_far_heights and halo == 1:
            _far_shadows(spec, ty, tx, lights, pos, nrm, terms, shadow, ray_offset(occluders), stats)
        del occluders
    colors = shade(lights, pos, nrm, shadow).reshape(m, res, res, 3)
    colors = weld_seam_light(ring_net, colors)[centre]
    texels = encode_half_bright(colors)
    # far field: the tile's patch-corner grid (exact surface points) and the texel at each corner
    py0, py1, px0, px1 = g.patch_range(ty, tx)
    ny, nx = py1 - py0, px1 - px0
    cp = ring_net.control_points[centre].reshape(ny, nx, 4, 4, 3)
    far = _corner_grid(cp)
    t = texels.reshape(ny, nx, res, res, 3)
    far_rgb = np.empty((ny + 1, nx + 1, 3), np.uint8)
    far_rgb[:-1, :-1] = t[:, :, 0, 0]
    far_rgb[:-1, -1] = t[:, -1, 0, res - 1]
    far_rgb[-1, :-1] = t[-1, :, res - 1, 0]
    far_rgb[-1, -1] = t[-1, -1, res - 1, res - 1]
    lo = cp.reshape(-1, 3).min(0)
    hi = cp.reshape(-1, 3).max(0)
    arrays = {"texels": texels, "far_positions": far, "far_colors": far_rgb,
              "far_error": far_errors(cp.reshape(-1, 4, 4, 3)),
              "meta": np.array([lo[2], hi[2], n], dtype=np.float64)}
    if spec.objects:
        kind, matrix = place_tile_objects(cp.reshape(-1, 4, 4, 3), g, ty, tx, spec.objects, spec.object_seed)
        arrays["objects_kind"], arrays["objects_matrix"] = kind, matrix
        stats["objects"] = len(kind)
    if spec.cell > 0:
        # eyes over this tile, targets and occluders the tile and its neighbours (every patch of the
        # 3 x 3 tiles, in row-major tile order: vis_meta "tiles" lists them with their patch counts)
        # the occluders no higher than the meshes the streaming renderer may draw for these tiles
        # (near, middle and the full corner grid: it uses the sets only while the tiles are drawn so)
        ring3, _ = neighbourhood_net(store, g, ty, tx, halo=1)
        x0, y0, x1, y1 = g.tile_bounds_xy(ty, tx)
        levels = sorted({max(res, NEAR_SAMPLES), MID_SAMPLES, 2})
        vis = compute_visibility(ring3, cell=spec.cell, eye_heights=spec.eye_heights, method="horizon", azimuths=180,
                                 region=(x0, y0, x1, y1), levels=levels, cover_ground=True)
        va, vm = vis.to_arrays()
        vm["levels"] = levels
        for k, v in va.items():
            arrays[f"vis_{k}"] = v
        vm["tiles"] = []
        for y in range(max(ty - 1, 0), min(ty + 2, g.shape[0])):
            for x in range(max(tx - 1, 0), min(tx + 2, g.shape[1])):
                qy0, qy1, qx0, qx1 = g.patch_range(y, x)
                vm["tiles"].append([y, x, (qy1 - qy0) * (qx1 - qx0)])
        arrays["vis_meta"] = np.array(_json(vm))
    info = {"samples": m * res * res, "rays": int(stats.get("rays", 0)), "far_rays": int(stats.get("far_rays", 0)),
            "objects": int(stats.get("objects", 0)), "zmin": float(lo[2]), "zmax": float(hi[2]),
            "patches": n}
    return arrays, info


def far_errors(control_points: np.ndarray, k: int = 9) -> np.ndarray:
    """How far a tile's patches ``(n, 4, 4, 3)`` leave the streaming renderer's coarse levels,
    ``(2,)`` float64 metres (the tile member ``far_error``): the largest vertical distance, over
    ``k x k`` points a patch, between the surface and (0) the patch-corner grid, (1) the middle
    level (every patch evaluated 3 samples a side).  The renderer picks a tile's level by these
    errors on screen (:class:`piste.render.streaming.TileCache`)."""
    t = np.linspace(0.0, 1.0, k)
    u, v = grid_params(k)
    cp = np.asarray(control_points, dtype=np.float64)
    z = evaluate(cp, u, v, normals=False)[..., 2].reshape(len(cp), k, k)  # [patch, j (v), i (u)]
    mid = (k - 1) // 2
    out = []
    for idx in ([0, k - 1], [0, mid, k - 1]):  # the levels' vertices among the k samples (k odd)
        out.append(float(np.abs(z - triangulated_heights(z[:, idx][:, :, idx], t)).max()) if len(cp) else 0.0)
    return np.array(out, dtype=np.float64)


def _json(d) -> str:
    import json

    return json.dumps(d, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))


# ----------------------------------------------------------------------------- the driver
def write_index(spec: TiledSpec, fits: dict, lits: dict, extra: dict | None = None) -> dict:
    """Write ``index.json`` (atomically) from the tasks' results; returns it."""
    g = spec.grid
    tiles = {}
    for (ty, tx) in g.tiles():
        f, lt = fits[(ty, tx)], lits[(ty, tx)]
        x0, y0, x1, y1 = g.tile_bounds_xy(ty, tx)
        tiles[f"{ty},{tx}"] = {"fit": f["sha256"], "lit": lt["sha256"], "patches": lt["patches"],
                               "bounds": [[x0, y0, lt["zmin"]], [x1, y1, lt["zmax"]]]}
    index = {"format": TILES_FORMAT, "name": spec.name, "grid": g.to_dict(), "patches": g.n_patches,
             "res": spec.res, "shadows": spec.shadows, "cell": spec.cell, "lights": spec.lights_toml,
             "source": spec.source_key(), "tiles": tiles, **(extra or {})}
    spec.store.write_index(index)
    return index


@dataclass
class TiledResult:
    root: Path
    index: dict
    seconds: float
    fit: dict
    lit: dict
    notes: list = field(default_factory=list)

    @property
    def built(self) -> int:
        return sum(not r["skipped"] for r in self.fit.values()) + sum(not r["skipped"] for r in self.lit.values())

    @property
    def skipped(self) -> int:
        return sum(r["skipped"] for r in self.fit.values()) + sum(r["skipped"] for r in self.lit.values())

    def summary(self) -> str:
        g = TileGrid.from_dict(self.index["grid"])
        samples = sum(r.get("samples", 0) for r in self.lit.values())
        bake_s = sum(r["seconds"] for r in self.lit.values())
        rate = f", bake {samples / bake_s:,.0f} samples/s" if bake_s > 0 and samples else ""
        return "\n".join([f"built {self.root} ({g.n_patches:,} patches in {g.shape[0]} x {g.shape[1]} tiles) in "
                          f"{self.seconds:.2f} s: {self.built} tile steps computed, {self.skipped} reused{rate}"]
                         + [f"  note: {n}" for n in self.notes])


def build_tiles(spec: TiledSpec, progress: bool = False) -> TiledResult:
    """Build every tile in this process (fit pass, then lit pass), then the index."""
    t0 = time.perf_counter()
    g = spec.grid
    spec.store.root.mkdir(parents=True, exist_ok=True)
    fits, lits = {}, {}
    for step, fn, out in (("fit", fit_task, fits), ("lit", lit_task, lits)):
        if step == "lit":
            far_heights_task(spec)  # after every fit, before any bake
        it = g.tiles()
        if progress:
            from tqdm import tqdm

            it = tqdm(it, desc=f"tiles: {step}", unit="tile", leave=False)
        for ty, tx in it:
            out[(ty, tx)] = fn(spec, ty, tx)
    index = write_index(spec, fits, lits)
    return TiledResult(spec.store.root, index, time.perf_counter() - t0, fits, lits)


def spec_from_scene(scene: SceneFile, root: str | os.PathLike[str] | None = None, res: int | None = None) -> TiledSpec:
    """The :class:`TiledSpec` of a scene whose terrain is a height field (``terrain.tiles``)."""
    ts = scene.terrain
    if ts.kind not in ("heightfield", "geotiff"):
        raise ConfigError(f"{scene.path}: a tiled build needs a height-field terrain (GeoTIFF, PNG or .npz), "
                          f"got terrain kind {ts.kind!r}")
    src = FileSource(ts)
    grid = TileGrid(src.shape, ts.samples_per_patch, ts.tile_patches, src.spacing)
    check_grid(grid)
    root = Path(root) if root is not None else (ts.tiles or Path(scene.path).with_suffix(".tiles"))
    # per-tile visibility costs ~15 s a tile at 16 cells (horizon sweeps, loaded 2-core machine): cells
    # of at least a quarter tile keep it to a fraction of the bake
    tile_m = ts.tile_patches * ts.samples_per_patch * max(src.spacing)
    cell = max(scene.visibility.cell, tile_m / 4.0) if scene.visibility.enabled else 0.0
    return TiledSpec(str(root), src, grid, dumps_lights(scene_lights(scene)), res=res or scene.lightmap.res,
                     shadows=scene.lightmap.shadows, cell=cell,
                     eye_heights=tuple(scene.visibility.eye_heights), name=scene.name,
                     objects=tuple(ObjectRule(**r.rule_fields()) for r in getattr(scene, "tile_objects", ())))


def synthetic_spec(root: str | os.PathLike[str], patches_side: int, samples_per_patch: int = 3, tile_patches: int = 64, spacing: float = 10.0,
                   seed: int = 0, res: int = 4, shadows: bool = True, cell: float = 0.0) -> TiledSpec:
    """A synthetic world of ``patches_side ** 2`` patches (for benchmarks and examples)."""
    n = patches_side * samples_per_patch + 1
    src = SyntheticSource((n, n), (spacing, spacing), seed)
    grid = TileGrid((n, n), samples_per_patch, tile_patches, (spacing, spacing))
    check_grid(grid)
    return TiledSpec(str(root), src, grid, "", res=res, shadows=shadows, cell=cell, name=f"synthetic {seed}")


def check_grid(grid: TileGrid) -> None:
    if grid.n_patches > 50_000_000:
        raise ValidationError(f"{grid.n_patches:,} patches: more than the 50 M a tiled world supports")
    if math.prod(grid.shape) > 1_000_000:
        raise ValidationError(f"{math.prod(grid.shape):,} tiles: raise tile_patches")
