"""Pre-computed visibility: for each cell of the course, the patches and objects that can be seen.

"Pre-process everything you can": the course's xy bounds are cut into square cells; for each cell
a few eye points are sampled (the cell's corners and centre, each at every height of
``eye_heights`` above the snow) and every patch and object is tested from them.  The result is a
bitset per cell (``np.packbits``, little bit order), stored in the bundle; at run time the camera's
cell selects the bitset and the renderer skips everything else before frustum culling.

Two tests:

``horizon`` (height-field terrain, the default for a net that is a graph over xy)
    A radial horizon sweep per eye: ``azimuths`` rays are marched outwards in steps of ``step``
    metres over a grid of the terrain's heights; the running maximum of the elevation slope
    ``(h - eye_z) / r`` along each ray is the horizon.  A target point is visible when its own
    slope reaches the horizon just before it (on its own azimuth or a neighbouring one).  Made
    conservative (more visible, never less) by using the terrain's *lower* envelope as occluder
    (the sampled heights min-filtered over 3x3 samples, minus ``margin``), lifting the targets by
    ``margin`` and taking the lowest horizon of three neighbouring azimuths.  Cost per eye:
    ``azimuths x (range / step)`` height look-ups, independent of the number of patches.
``rays`` (any net)
    Exact segments from each eye to each target point through the terrain's BVH
    (:func:`piste.terrain.query.ray_intersect`, any-hit): a target is visible when a segment
    reaches it unblocked.  ~40 k rays/s: for small nets (the teapot) or for checking ``horizon``.

Targets: each patch's 3 x 3 points at parameters (0.1, 0.5, 0.9); each object's bounding-sphere
centre and top.  Eye points are samples: an eye between them may (rarely) see a little more.

API
---
Visibility                                   grid + bitsets; ``patches_at(eye)``, ``objects_at(eye)``
compute_visibility(net, cell, eye_heights, objects=None, method="auto", region=None, levels=()) -> Visibility
drawn_floor(net, patch, uv, levels) -> (k,)    the lowest of the triangulated m x m meshes at (patch, uv)
culling_report(net, vis, cameras) -> dict    % of patches drawn: frustum alone vs frustum + visibility
scene_eye_heights(net, base, eyes) -> heights  the band a scene needs (its cameras' and riders' eyes)
band_warnings(net, vis, cameras) -> messages   cameras above the band (their frames draw without the sets)

The band: the sets hold for eyes from the snow up to the highest sampled height (on a height field
an eye sees no less from higher up); a set per sampled height (``level_bits``) keeps the culling
of low eyes when the band reaches high: an eye gets the set of the lowest sampled height at or
above its own.  An eye above it (measured from its cell's lowest sampled
ground) gets no set, so everything is drawn: culling is lost there, never a pixel.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from piste._data import DataMethods
from piste.errors import ConfigError, FormatError
from piste.terrain.bezier import evaluate, grid_params
from piste.terrain.query import height_at, ray_intersect
from piste.transforms import cull_boxes
from piste.world.camera import track_camera

if TYPE_CHECKING:
    import numpy.typing as npt

    from piste.terrain.net import PatchNet
    from piste.world.camera import Camera

__all__ = ["Visibility", "compute_visibility", "culling_report", "patch_targets", "is_heightfield", "height_above",
           "scene_eye_heights", "band_warnings", "camera_eyes", "drawn_floor"]

#: most eye-point x target tests one visibility computation may allocate (bytes of booleans)
MAX_VISIBILITY_WORK = 2 << 30


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Visibility(DataMethods):
    """Per-cell visibility bitsets.

    Attributes
    ----------
    origin : (2,) float64, xy of the grid's corner;  cell : metres;  shape : (rows, cols) (rows along y)
    patch_bits : (rows * cols, ceil(n / 8)) uint8, little bit order: bit ``p`` of row ``c`` set when
        patch ``p`` is visible from cell ``c``
    object_bits : (rows * cols, ceil(m / 8)) uint8, the same for objects
    n_patches, n_objects : int;  method : str;  eye_heights : tuple
    """

    origin: np.ndarray
    cell: float
    shape: tuple
    patch_bits: np.ndarray
    object_bits: np.ndarray
    n_patches: int
    n_objects: int
    method: str = "horizon"
    eye_heights: tuple = (1.7, 9.0)
    ground_min: np.ndarray | None = None  # (cells,) lowest sampled ground of each cell (the band's floor)
    level_bits: np.ndarray | None = None  # (levels - 1, cells, ceil(n / 8)): patches seen from eyes up to
    #                                       each lower sampled height (the top level is patch_bits)

    @property
    def band(self) -> float:
        """Metres above the snow up to which the sets hold (the highest sampled eye: on a height
        field an eye sees no less from higher up, so the top sample covers the band below it)."""
        return float(max(self.eye_heights)) if self.eye_heights else 0.0

    def in_band(self, eye: npt.ArrayLike) -> bool:
        """Whether ``eye (3,)`` is within the band over its cell (conservatively: measured from the
        cell's lowest sampled ground); True outside the grid (nothing is culled there anyway)."""
        c = self.cell_of(eye)
        if c < 0 or self.ground_min is None:
            return True
        return float(np.asarray(eye, dtype=np.float64).reshape(-1)[2]) <= float(self.ground_min[c]) + self.band

    def cell_of(self, eye: npt.ArrayLike) -> int:
        """Cell index of an eye position ``(3,)`` (or ``(2,)``), -1 outside the grid."""
        e = np.asarray(eye, dtype=np.float64).reshape(-1)[:2]
        ij = np.floor((e - self.origin) / self.cell).astype(np.int64)
        rows, cols = self.shape
        if not (0 <= ij[0] < cols and 0 <= ij[1] < rows):
            return -1
        return int(ij[1] * cols + ij[0])

    def patches_at(self, eye: npt.ArrayLike) -> np.ndarray | None:
        """``(n,) bool`` patches visible from the cell holding ``eye``; None outside the grid or above
        the band (:meth:`in_band`): draw all."""
        c = self.cell_of(eye)
        if c < 0 or not self.in_band(eye):  # above the sampled band: the sets may miss what it sees
            return None
        bits = self.patch_bits[c]
        if self.level_bits is not None and self.ground_min is not None and len(self.level_bits):
            # the lowest sampled height at or above the eye's (measured from the cell's lowest ground)
            h = float(np.asarray(eye, dtype=np.float64).reshape(-1)[2]) - float(self.ground_min[c])
            j = int(np.searchsorted(np.asarray(self.eye_heights, dtype=np.float64), h - 1e-9))
            if j < len(self.level_bits):
                bits = self.level_bits[j, c]
        return np.unpackbits(bits, count=self.n_patches, bitorder="little").astype(bool)

    def objects_at(self, eye: npt.ArrayLike) -> np.ndarray | None:
        """``(m,) bool`` objects visible from the cell holding ``eye``; None outside the grid."""
        c = self.cell_of(eye)
        if c < 0 or not self.in_band(eye):
            return None
        return np.unpackbits(self.object_bits[c], count=self.n_objects, bitorder="little").astype(bool)

    def patch_matrix(self) -> np.ndarray:
        """All cells' patch visibility ``(cells, n) bool``."""
        return np.unpackbits(self.patch_bits, axis=1, count=self.n_patches, bitorder="little").astype(bool)

    def to_arrays(self) -> tuple[dict, dict]:
        """``(arrays, meta)`` for a bundle or the cache."""
        arrays = {"patch_bits": self.patch_bits, "object_bits": self.object_bits}
        if self.ground_min is not None:
            arrays["ground_min"] = np.asarray(self.ground_min, np.float32)
        if self.level_bits is not None:
            arrays["level_bits"] = self.level_bits
        meta = {"origin": [float(x) for x in self.origin], "cell": float(self.cell), "shape": [int(x) for x in self.shape],
                "n_patches": int(self.n_patches), "n_objects": int(self.n_objects), "method": self.method,
                "eye_heights": [float(x) for x in self.eye_heights]}
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict) -> "Visibility":
        cells = int(np.prod(meta["shape"]))
        pb = np.asarray(arrays["patch_bits"])
        gm, lb = arrays.get("ground_min"), arrays.get("level_bits")
        if gm is not None and np.shape(gm) != (cells,):
            raise FormatError(None, f"expected ({cells},) cell ground heights, got {np.shape(gm)}",
                              field="visibility/ground_min")
        if lb is not None and (np.ndim(lb) != 3 or np.shape(lb)[1:] != pb.shape
                               or np.shape(lb)[0] >= max(len(meta.get("eye_heights", ())), 1)):
            raise FormatError(None, f"expected (levels < {len(meta.get('eye_heights', ()))}, {pb.shape[0]}, "
                                    f"{pb.shape[1] if pb.ndim == 2 else '?'}) level bits, got {np.shape(lb)}",
                              field="visibility/level_bits")
        return cls(np.asarray(meta["origin"], dtype=np.float64), float(meta["cell"]), tuple(meta["shape"]),
                   arrays["patch_bits"], arrays["object_bits"], int(meta["n_patches"]), int(meta["n_objects"]),
                   meta.get("method", "horizon"), tuple(meta.get("eye_heights", ())),
                   np.asarray(arrays["ground_min"], np.float64) if "ground_min" in arrays else None,
                   arrays.get("level_bits"))


# ----------------------------------------------------------------------------- targets, eyes
def patch_targets(net: PatchNet, params: Sequence[float] = (0.1, 0.5, 0.9)) -> np.ndarray:
    """Sample points of every patch, ``(n, k*k, 3)`` float64, at parameters ``params`` x ``params``."""
    p = np.asarray(params, dtype=np.float64)
    u, v = np.meshgrid(p, p, indexing="ij")
    pts = evaluate(net.control_points, u.ravel(), v.ravel(), normals=False)
    return np.asarray(pts[0] if isinstance(pts, tuple) else pts, dtype=np.float64)


def is_heightfield(net: PatchNet, samples: int = 64) -> bool:
    """Whether the net is a graph over xy (each patch's xy map is one-to-one and patches don't
    overlap): tested on the patches' sample points (z up normals everywhere, cells covered once)."""
    t = np.linspace(0.02, 0.98, 5)
    u, v = np.meshgrid(t, t, indexing="ij")
    out = evaluate(net.control_points, u.ravel(), v.ravel(), normals=True)
    if not isinstance(out, tuple):
        return False
    nrm = np.asarray(out[1])
    nz = nrm[..., 2] / np.maximum(np.linalg.norm(nrm, axis=-1), 1e-300)
    if not ((nz > 0.05).all() or (nz < -0.05).all()):
        return False
    # overlap check: patch xy boxes may touch but the summed box area must not exceed the hull's much
    lo, hi = net.patch_bounds
    area = np.prod(hi[:, :2] - lo[:, :2], axis=1).sum()
    blo, bhi = net.bounds
    return bool(area <= 1.05 * np.prod(bhi[:2] - blo[:2]) + 1e-9)


def _grid_for(net: PatchNet, cell: float, region: np.ndarray | None = None) -> tuple[np.ndarray, tuple[int, int]]:
    lo, hi = net.bounds
    if region is not None:  # the eyes' cells over part of the net (e.g. a tile of its neighbourhood)
        lo = np.array([region[0], region[1], lo[2]], dtype=np.float64)
        hi = np.array([region[2], region[3], hi[2]], dtype=np.float64)
    origin = lo[:2].copy()
    cols = max(1, int(np.ceil((hi[0] - lo[0]) / cell - 1e-9)))
    rows = max(1, int(np.ceil((hi[1] - lo[1]) / cell - 1e-9)))
    return origin, (rows, cols)


def _eye_points(net: PatchNet, origin: np.ndarray, shape: tuple[int, int], cell: float, eye_heights: Sequence[float],
                region: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eye points and which cells they serve: ``eyes (k, 3)``, ``owner`` list of (cell, eye) pairs."""
    rows, cols = shape
    lo, hi = net.bounds
    if region is not None:
        lo, hi = np.asarray(region[:2], dtype=np.float64), np.asarray(region[2:], dtype=np.float64)
    inset = 1e-3 * cell
    gx = np.clip(origin[0] + cell * np.arange(cols + 1), lo[0] + inset, hi[0] - inset)
    gy = np.clip(origin[1] + cell * np.arange(rows + 1), lo[1] + inset, hi[1] - inset)
    cx = np.clip(origin[0] + cell * (np.arange(cols) + 0.5), lo[0] + inset, hi[0] - inset)
    cy = np.clip(origin[1] + cell * (np.arange(rows) + 0.5), lo[1] + inset, hi[1] - inset)
    corners = np.stack(np.meshgrid(gx, gy, indexing="xy"), -1).reshape(-1, 2)  # node (r, c) at r*(cols+1)+c
    centres = np.stack(np.meshgrid(cx, cy, indexing="xy"), -1).reshape(-1, 2)  # cell r*cols+c
    xy = np.concatenate([corners, centres])
    z, hit, _, _ = height_at(net, xy)
    r, c = np.divmod(np.arange(rows * cols), cols)
    nodes = np.stack([r * (cols + 1) + c, r * (cols + 1) + c + 1, (r + 1) * (cols + 1) + c, (r + 1) * (cols + 1) + c + 1,
                      len(corners) + np.arange(rows * cols)], 1)  # (cells, 5) ground points of each cell
    return xy, z, hit, nodes


# ----------------------------------------------------------------------------- the horizon test
def drawn_floor(net: PatchNet, patch: np.ndarray, uv: np.ndarray, levels: Iterable[int]) -> np.ndarray:
    """The lowest of the triangulated meshes a renderer may draw for ``net``'s patches: at points
    ``(patch (k,), uv (k, 2))``, the minimum over ``levels`` (samples a patch side, e.g. 2: the
    patch-corner grid) of the patch evaluated on an ``m x m`` grid, each cell split along its
    (0, 0)-(1, 1) diagonal (as :func:`piste.terrain.tiles.triangulated_heights` and the streamed
    tile meshes are), ``(k,)`` float64 (+inf without levels)."""
    patch = np.asarray(patch, dtype=np.int64)
    u, v = np.asarray(uv, dtype=np.float64)[:, 0], np.asarray(uv, dtype=np.float64)[:, 1]
    out = np.full(len(patch), np.inf)
    cp = np.asarray(net.control_points, dtype=np.float64)
    for m in sorted({int(x) for x in levels}):
        gu, gv = grid_params(m)
        z = cast(np.ndarray, evaluate(cp, gu, gv, normals=False))[..., 2].reshape(len(cp), m, m)  # [patch, j (v), i (u)]
        s, t = np.clip(u, 0.0, 1.0) * (m - 1), np.clip(v, 0.0, 1.0) * (m - 1)
        i = np.minimum(np.floor(s).astype(np.int64), m - 2)
        j = np.minimum(np.floor(t).astype(np.int64), m - 2)
        fu, fv = s - i, t - j
        z00, z10 = z[patch, j, i], z[patch, j, i + 1]
        z01, z11 = z[patch, j + 1, i], z[patch, j + 1, i + 1]
        lower = z00 + fu * (z10 - z00) + fv * (z11 - z10)  # fu >= fv: the triangle (00, 10, 11)
        upper = z00 + fv * (z01 - z00) + fu * (z11 - z01)  # the triangle (00, 11, 01)
        out = np.minimum(out, np.where(fu >= fv, lower, upper))
    return out


class _HeightGrid:
    """The terrain's lower envelope on a regular grid (occluder heights), -inf off the terrain;
    with ``levels``, also no higher than the coarser meshes drawn for it (:func:`drawn_floor`)."""

    def __init__(self, net: PatchNet, spacing: float, margin: float, levels: Sequence[int] = ()) -> None:
        from scipy.ndimage import minimum_filter

        lo, hi = net.bounds
        self.origin = lo[:2]
        self.spacing = float(spacing)
        nx = int(np.ceil((hi[0] - lo[0]) / spacing)) + 1
        ny = int(np.ceil((hi[1] - lo[1]) / spacing)) + 1
        x = lo[0] + spacing * np.arange(nx)
        y = lo[1] + spacing * np.arange(ny)
        xy = np.stack(np.meshgrid(np.minimum(x, hi[0]), np.minimum(y, hi[1]), indexing="xy"), -1).reshape(-1, 2)
        z, hit, patch, uv = height_at(net, xy)
        if len(levels) and hit.any():
            z = z.copy()
            z[hit] = np.minimum(z[hit], drawn_floor(net, patch[hit], uv[hit], levels))
        z = np.where(hit, z, np.inf).reshape(ny, nx)
        z = minimum_filter(z, size=3, mode="nearest") - margin
        self.h = np.where(np.isfinite(z), z, -np.inf)
        self.shape = (ny, nx)

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """Occluder heights at ``xy (..., 2)`` (nearest grid point), -inf outside."""
        ij = np.rint((xy - self.origin) / self.spacing).astype(np.int64)
        ix, iy = ij[..., 0], ij[..., 1]
        ny, nx = self.shape
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        out = np.full(ix.shape, -np.inf)
        out[ok] = self.h[iy[ok], ix[ok]]
        return out


def _horizon_visible(grid: _HeightGrid, eyes: np.ndarray, targets: np.ndarray, azimuths: int, step: float,
                     rmax: float, margin: float, batch: int = 4) -> np.ndarray:
    """``(e, t) bool``: target points visible from each eye (see the module docstring)."""
    n_r = int(np.ceil(rmax / step)) + 1
    r = step * np.arange(1, n_r + 1)  # (R,)
    ang = 2.0 * np.pi * np.arange(azimuths) / azimuths
    dirs = np.stack([np.cos(ang), np.sin(ang)], -1)  # (A, 2)
    out = np.zeros((len(eyes), len(targets)), dtype=bool)
    tz = targets[:, 2] + margin
    for b0 in range(0, len(eyes), batch):
        e = eyes[b0:b0 + batch]  # (b, 3)
        xy = e[:, None, None, :2] + dirs[None, :, None, :] * r[None, None, :, None]  # (b, A, R, 2)
        slope = (grid.sample(xy) - e[:, None, None, 2:3][..., 0]) / r  # (b, A, R)
        horizon = np.maximum.accumulate(slope, axis=2)
        # the horizon just before each radius: shift by one step (nothing before the first)
        before = np.concatenate([np.full(horizon.shape[:2] + (1,), -np.inf), horizon[:, :, :-1]], axis=2)
        # lowest horizon of three neighbouring azimuths
        low = np.minimum(before, np.minimum(np.roll(before, 1, axis=1), np.roll(before, -1, axis=1)))
        d = targets[None, :, :2] - e[:, None, :2]  # (b, t, 2)
        dist = np.hypot(d[..., 0], d[..., 1])
        a_idx = np.rint(np.arctan2(d[..., 1], d[..., 0]) / (2.0 * np.pi) * azimuths).astype(np.int64) % azimuths
        # occluders must lie at least one step (and one grid cell) before the target
        r_idx = np.floor((dist - grid.spacing) / step).astype(np.int64) - 1
        bi = np.arange(len(e))[:, None]
        h = np.where(r_idx >= 0, low[bi, a_idx, np.clip(r_idx, 0, n_r - 1)], -np.inf)
        t_slope = (tz[None, :] - e[:, None, 2]) / np.maximum(dist, 1e-9)
        out[b0:b0 + batch] = (t_slope >= h) | (dist < 2.0 * step)
    return out


def _rays_visible(net: PatchNet, eyes: np.ndarray, targets: np.ndarray, margin: float) -> np.ndarray:
    tgt = targets + np.array([0.0, 0.0, margin])
    o = np.repeat(eyes, len(tgt), axis=0)
    d = np.tile(tgt, (len(eyes), 1)) - o
    ok = np.linalg.norm(d, axis=1) > 1e-9
    vis = np.ones(len(o), dtype=bool)
    if ok.any():
        hits = ray_intersect(net, o[ok], d[ok], t_max=1.0 - 1e-6, t_min=1e-6, any_hit=True)
        vis[np.nonzero(ok)[0]] = ~hits.hit
    return vis.reshape(len(eyes), len(tgt))


# ----------------------------------------------------------------------------- the step
def compute_visibility(net: PatchNet, cell: float = 50.0, eye_heights: Sequence[float] = (1.7, 9.0),
                       objects: npt.ArrayLike | None = None, method: str = "auto",
                       azimuths: int = 720, step: float | None = None, margin: float = 0.25,
                       progress: bool = False, patches: bool = True, region: npt.ArrayLike | None = None,
                       levels: Sequence[int] = (),
                       cover_ground: bool = False) -> Visibility:
    """Visibility bitsets of ``net``'s patches (and objects) for a grid of ``cell``-metre cells.

    Parameters
    ----------
    net : PatchNet
    cell : cell size in metres
    eye_heights : metres above the snow of the sampled eyes
    objects : None, or ``(m, 4)`` float bounding spheres ``(x, y, z, radius)`` of the placed objects
    method : "horizon" (height fields), "rays" (exact, slow) or "auto" (horizon when the net is a
        height field, else rays)
    azimuths, step : horizon rays per eye and metres per march step (default: a quarter patch)
    margin : metres of conservative slack (occluders lowered, targets raised)
    progress : tqdm bar over eye batches
    patches : test the patches (False: only the objects; every patch bit is set), so that moving an
        object recomputes only the objects' bits (with ``method="rays"`` that is cheap for a few objects)
    region : ``(x0, y0, x1, y1)`` metres inside the net's bounds: the cells (the eyes) cover only
        this rectangle while every patch of the net is a target and an occluder (a tiled world's
        tile, its sets saying what it sees of its neighbours too); default: the net's bounds
    levels : samples a patch side of coarser meshes a renderer draws instead of the exact surface
        (horizon method): occluders are lowered to the lowest of them (:func:`drawn_floor`), so a
        target hidden by the exact surface but not by a coarse mesh that sags below it stays visible
    cover_ground : also sample eyes at the highest of ``eye_heights`` plus the largest rise of
        sampled ground within a cell (metres, rounded up), so the band (measured from a cell's lowest
        sampled ground) reaches an eye at that height over the cell's highest sampled ground: on
        steep ground the sets still hold there (with ``level_bits``, low eyes keep the tighter sets)
    """
    if not cell > 0:
        raise ConfigError(f"visibility: cell must be > 0 metres, got {cell}")
    heights = tuple(sorted({float(h) for h in eye_heights}))
    if not heights:
        raise ConfigError("visibility: eye_heights must name at least one height")
    if method == "auto":
        method = "horizon" if is_heightfield(net) else "rays"
    if method not in ("horizon", "rays"):
        raise ConfigError(f"visibility: method must be 'auto', 'horizon' or 'rays', got {method!r}")
    n = len(net)
    spheres = np.zeros((0, 4)) if objects is None else np.asarray(objects, dtype=np.float64).reshape(-1, 4)
    m = len(spheres)
    if region is not None:
        region = np.asarray(region, dtype=np.float64).reshape(-1)
        lo, hi = net.bounds
        if region.shape != (4,) or not np.isfinite(region).all() or not (region[0] < region[2] and region[1] < region[3]) \
                or region[0] < lo[0] - 1e-6 or region[1] < lo[1] - 1e-6 or region[2] > hi[0] + 1e-6 \
                or region[3] > hi[1] + 1e-6:
            raise ConfigError(f"visibility: region must be (x0, y0, x1, y1) inside the terrain's bounds "
                              f"{lo[:2].tolist()} .. {hi[:2].tolist()}, got {region.tolist()}")
    origin, shape = _grid_for(net, cell, region)
    rows, cols = shape
    # bound the work before allocating: (eye points x targets) booleans (a tiny cell asked for TiBs)
    def check_work(heights: Sequence[float]) -> None:
        work = ((rows + 1) * (cols + 1) + rows * cols) * len(heights) * (n * (9 if patches else 0) + 2 * m)
        if work > MAX_VISIBILITY_WORK:
            raise ConfigError(f"visibility: a cell of {cell:g} m cuts the course into {rows} x {cols} cells, "
                              f"{work / 2**30:.1f} GiB of eye-target tests (limit {MAX_VISIBILITY_WORK / 2**30:.0f} "
                              "GiB): use a larger visibility.cell")

    check_work(heights)
    xy, zg, hit, nodes = _eye_points(net, origin, shape, cell, heights, region)
    if cover_ground:
        g5 = np.where(hit, zg, np.nan)[nodes]  # (cells, 5) sampled ground
        ok = np.isfinite(g5).any(axis=1)
        if ok.any():
            rise = float((np.nanmax(g5[ok], axis=1) - np.nanmin(g5[ok], axis=1)).max())
            extra = [float(np.ceil(max(heights) + rise))]
            while extra[-1] / 2.0 > 2.0 * max(heights):  # and halving down: eyes between get tighter sets
                extra.append(float(np.ceil(extra[-1] / 2.0)))
            heights = tuple(sorted(set(heights) | {h for h in extra if h > max(heights)}))
            check_work(heights)
    ptargets = patch_targets(net) if patches else np.zeros((n, 0, 3))  # (n, 9, 3)
    k = ptargets.shape[1]
    otargets = np.concatenate([spheres[:, :3], spheres[:, :3] + np.stack([np.zeros(m), np.zeros(m), spheres[:, 3]], 1)])
    targets = np.concatenate([ptargets.reshape(-1, 3), otargets])
    eyes = np.concatenate([np.column_stack([xy, zg + h]) for h in heights])  # (g * H, 3)
    valid: np.ndarray = np.tile(hit, len(heights))
    vis_eye = np.zeros((len(eyes), len(targets)), dtype=bool)
    idx = np.nonzero(valid)[0]
    if method == "horizon":
        lo, hi = net.bounds
        size = float(np.median(net.patch_size))
        st = float(step) if step is not None else max(size / 4.0, 0.25)
        grid = _HeightGrid(net, st, margin, levels)
        rmax = float(np.hypot(*(hi[:2] - lo[:2])))
        chunks = [idx[i:i + 4] for i in range(0, len(idx), 4)]
        it = chunks
        if progress:
            from tqdm import tqdm

            it = tqdm(chunks, desc="visibility", unit="eyes", leave=False)
        for ch in it:
            vis_eye[ch] = _horizon_visible(grid, eyes[ch], targets, int(azimuths), st, rmax, margin, batch=len(ch))
    else:
        per = max(1, 100_000 // max(len(targets), 1))  # eyes a batch: ~100k rays traced together
        chunks = [idx[i:i + per] for i in range(0, len(idx), per)]
        it = chunks
        if progress:
            from tqdm import tqdm

            it = tqdm(chunks, desc="visibility (rays)", unit="eyes", leave=False)
        for ch in it:
            vis_eye[ch] = _rays_visible(net, eyes[ch], targets, margin)
    # per ground point and level: union over the heights up to it (the top level: all heights);
    # per cell: union over its five ground points
    g = len(xy)
    per_level = np.logical_or.accumulate(vis_eye.reshape(len(heights), g, -1), axis=0)  # (H, g, targets)
    point_valid = cast(np.ndarray, valid.reshape(len(heights), g).any(axis=0))  # (g,) bool
    cells = rows * cols
    cell_ok = np.zeros(cells, dtype=bool)
    for j in range(nodes.shape[1]):
        cell_ok |= point_valid[nodes[:, j]]
    levels_p, levels_o = [], []
    for per_point in per_level:
        cell_vis = np.zeros((cells, len(targets)), dtype=bool)
        for j in range(nodes.shape[1]):
            cell_vis |= per_point[nodes[:, j]]
        cell_vis[~cell_ok] = True  # no eye on the terrain: keep everything
        pv = cell_vis[:, : n * k].reshape(cells, n, k).any(axis=2) if k else np.ones((cells, n), dtype=bool)
        ov = cell_vis[:, n * k:].reshape(cells, 2, m).any(axis=1) if m else np.zeros((cells, 0), bool)
        levels_p.append(np.packbits(pv, axis=1, bitorder="little"))
        levels_o.append(np.packbits(ov, axis=1, bitorder="little") if m else np.zeros((cells, 0), np.uint8))
    pbits, obits = levels_p[-1], levels_o[-1]
    lbits = np.stack(levels_p[:-1]) if len(levels_p) > 1 and k else None
    gz = np.where(hit, zg, np.inf)[nodes].min(axis=1)  # each cell's lowest sampled ground
    gz = np.where(np.isfinite(gz), gz, -np.inf)  # no ground sampled: every eye is "in band"... and all is kept
    return Visibility(origin, float(cell), shape, pbits, obits, n, m, method, heights, gz, lbits)


def height_above(net: PatchNet, eyes: npt.ArrayLike) -> np.ndarray:
    """``(k,)`` metres of each eye ``(k, 3)`` above the terrain under it (NaN off the terrain)."""
    e = np.asarray(eyes, dtype=np.float64).reshape(-1, 3)
    z, hit, _, _ = height_at(net, e[:, :2])
    return np.where(hit, e[:, 2] - z, np.nan)


def scene_eye_heights(net: PatchNet, base: Iterable[float] = (1.7, 9.0), eyes: npt.ArrayLike = (), cell: float = 50.0,
                      slack: float = 1.1) -> tuple[float, ...]:
    """The heights above the snow to sample for a scene: ``base`` plus the band's top, the highest
    of ``eyes (k, 3)`` (its cameras along their paths, its riders' heads) above the lowest ground
    within a ``cell`` around it (what :meth:`Visibility.in_band` measures from), times ``slack``,
    rounded up to a metre.  Visibility from a height field only grows with the eye's height, so
    sets sampled up to the top hold for every eye the scene's cameras reach."""
    heights = sorted({float(h) for h in base})
    e = np.asarray(eyes, dtype=np.float64).reshape(-1, 3)
    if len(e):
        off = np.stack(np.meshgrid(*(np.linspace(-cell, cell, 5),) * 2, indexing="xy"), -1).reshape(-1, 2)
        xy = (e[:, None, :2] + off[None]).reshape(-1, 2)
        z, hit, _, _ = height_at(net, xy)
        ground = np.where(hit, z, np.inf).reshape(len(e), -1).min(axis=1)
        h = e[:, 2] - ground
        h = h[np.isfinite(h)]
        if len(h):
            top = float(np.ceil(h.max() * slack))
            if top > heights[-1]:
                heights.append(top)
    return tuple(heights)


def camera_eyes(cameras: Iterable[Mapping[str, Any]], centerline: np.ndarray | None = None, samples: int = 16) -> np.ndarray:
    """Every eye ``(k, 3)`` the scene's cameras (bundle manifest dicts) reach: fixed eyes, and
    ``samples`` points along each track camera's flight."""
    out = []
    for c in cameras:
        if c.get("track") and centerline is not None:
            a, b = c["track"]
            for f in np.linspace(float(a), float(b), samples):
                out.append(track_camera(centerline, float(f), height=c.get("height", 9.0)).eye)
        elif c.get("eye") is not None:
            out.append(np.asarray(c["eye"], dtype=np.float64))
    return np.asarray(out, dtype=np.float64).reshape(-1, 3)


def band_warnings(net: PatchNet, vis: Visibility, cameras: Iterable[Camera], names: Sequence[str] | None = None
                  ) -> list[str]:
    """A message per camera (``cameras``: Camera objects; ``names``: their labels) whose eye is
    above the visibility band (:meth:`Visibility.in_band`): the sets are not used there (every
    patch drawn), so culling is lost, never pixels."""
    out = []
    for i, cam in enumerate(cameras):
        if not vis.in_band(cam.eye):
            h = height_above(net, cam.eye)[0]
            label = names[i] if names is not None else f"camera {i}"
            out.append(f"{label} is {h:.1f} m above the terrain, above the visibility band ({vis.band:g} m): "
                       f"its frames draw without the visibility sets (add its height to [visibility] eye_heights "
                       f"or rebuild: the build derives the band from the scene's cameras)")
    return out


def culling_report(net: PatchNet, vis: Visibility, cameras: Iterable[Camera]) -> dict[str, Any]:
    """Patches drawn with frustum culling alone vs frustum culling and the visibility sets.

    Parameters
    ----------
    cameras : iterable of :class:`piste.world.camera.Camera` (e.g. along the track)

    Returns
    -------
    dict: ``frames``, ``patches``, ``frustum_pct`` and ``visible_pct`` (mean % of all patches
    drawn), ``drawn_ratio`` (visible / frustum), ``saved_pct`` (100 * (1 - ratio)).
    """
    lo, hi = net.patch_bounds
    centre = np.ascontiguousarray(((lo + hi) / 2.0).T)
    half = np.ascontiguousarray(((hi - lo) / 2.0).T)
    fr, pv = [], []
    for cam in cameras:
        f = cull_boxes(centre, half, cam.frustum_planes())
        s = vis.patches_at(cam.eye)
        fr.append(int(f.sum()))
        pv.append(int((f & s).sum()) if s is not None else int(f.sum()))
    n = len(net)
    fr_a, pv_a = np.asarray(fr, float), np.asarray(pv, float)
    ratio = float(pv_a.sum() / fr_a.sum()) if fr_a.sum() else 1.0
    return {
        "frames": len(fr),
        "patches": n,
        "frustum_pct": float(100.0 * fr_a.mean() / n) if len(fr) else 0.0,
        "visible_pct": float(100.0 * pv_a.mean() / n) if len(fr) else 0.0,
        "drawn_ratio": ratio,
        "saved_pct": 100.0 * (1.0 - ratio),
    }
