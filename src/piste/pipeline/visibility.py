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
compute_visibility(net, cell, eye_heights, objects=None, method="auto") -> Visibility
culling_report(net, vis, cameras) -> dict    % of patches drawn: frustum alone vs frustum + visibility
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from piste.errors import ConfigError
from piste.terrain.bezier import evaluate
from piste.terrain.query import height_at, ray_intersect
from piste.transforms import cull_boxes

__all__ = ["Visibility", "compute_visibility", "culling_report", "patch_targets", "is_heightfield"]

#: most eye-point x target tests one visibility computation may allocate (bytes of booleans)
MAX_VISIBILITY_WORK = 2 << 30


@dataclass
class Visibility:
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

    def cell_of(self, eye) -> int:
        """Cell index of an eye position ``(3,)`` (or ``(2,)``), -1 outside the grid."""
        e = np.asarray(eye, dtype=np.float64).reshape(-1)[:2]
        ij = np.floor((e - self.origin) / self.cell).astype(np.int64)
        rows, cols = self.shape
        if not (0 <= ij[0] < cols and 0 <= ij[1] < rows):
            return -1
        return int(ij[1] * cols + ij[0])

    def patches_at(self, eye) -> np.ndarray | None:
        """``(n,) bool`` patches visible from the cell holding ``eye``; None outside the grid (draw all)."""
        c = self.cell_of(eye)
        if c < 0:
            return None
        return np.unpackbits(self.patch_bits[c], count=self.n_patches, bitorder="little").astype(bool)

    def objects_at(self, eye) -> np.ndarray | None:
        """``(m,) bool`` objects visible from the cell holding ``eye``; None outside the grid."""
        c = self.cell_of(eye)
        if c < 0:
            return None
        return np.unpackbits(self.object_bits[c], count=self.n_objects, bitorder="little").astype(bool)

    def patch_matrix(self) -> np.ndarray:
        """All cells' patch visibility ``(cells, n) bool``."""
        return np.unpackbits(self.patch_bits, axis=1, count=self.n_patches, bitorder="little").astype(bool)

    def to_arrays(self) -> tuple[dict, dict]:
        """``(arrays, meta)`` for a bundle or the cache."""
        arrays = {"patch_bits": self.patch_bits, "object_bits": self.object_bits}
        meta = {"origin": [float(x) for x in self.origin], "cell": float(self.cell), "shape": [int(x) for x in self.shape],
                "n_patches": int(self.n_patches), "n_objects": int(self.n_objects), "method": self.method,
                "eye_heights": [float(x) for x in self.eye_heights]}
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict) -> "Visibility":
        return cls(np.asarray(meta["origin"], dtype=np.float64), float(meta["cell"]), tuple(meta["shape"]),
                   arrays["patch_bits"], arrays["object_bits"], int(meta["n_patches"]), int(meta["n_objects"]),
                   meta.get("method", "horizon"), tuple(meta.get("eye_heights", ())))


# ----------------------------------------------------------------------------- targets, eyes
def patch_targets(net, params=(0.1, 0.5, 0.9)) -> np.ndarray:
    """Sample points of every patch, ``(n, k*k, 3)`` float64, at parameters ``params`` x ``params``."""
    p = np.asarray(params, dtype=np.float64)
    u, v = np.meshgrid(p, p, indexing="ij")
    pts = evaluate(net.control_points, u.ravel(), v.ravel(), normals=False)
    return np.asarray(pts[0] if isinstance(pts, tuple) else pts, dtype=np.float64)


def is_heightfield(net, samples: int = 64) -> bool:
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


def _grid_for(net, cell: float):
    lo, hi = net.bounds
    origin = lo[:2].copy()
    cols = max(1, int(np.ceil((hi[0] - lo[0]) / cell - 1e-9)))
    rows = max(1, int(np.ceil((hi[1] - lo[1]) / cell - 1e-9)))
    return origin, (rows, cols)


def _eye_points(net, origin, shape, cell, eye_heights):
    """Eye points and which cells they serve: ``eyes (k, 3)``, ``owner`` list of (cell, eye) pairs."""
    rows, cols = shape
    lo, hi = net.bounds
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
class _HeightGrid:
    """The terrain's lower envelope on a regular grid (occluder heights), -inf off the terrain."""

    def __init__(self, net, spacing: float, margin: float):
        from scipy.ndimage import minimum_filter

        lo, hi = net.bounds
        self.origin = lo[:2]
        self.spacing = float(spacing)
        nx = int(np.ceil((hi[0] - lo[0]) / spacing)) + 1
        ny = int(np.ceil((hi[1] - lo[1]) / spacing)) + 1
        x = lo[0] + spacing * np.arange(nx)
        y = lo[1] + spacing * np.arange(ny)
        xy = np.stack(np.meshgrid(np.minimum(x, hi[0]), np.minimum(y, hi[1]), indexing="xy"), -1).reshape(-1, 2)
        z, hit, _, _ = height_at(net, xy)
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


def _rays_visible(net, eyes: np.ndarray, targets: np.ndarray, margin: float) -> np.ndarray:
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
def compute_visibility(net, cell: float = 50.0, eye_heights=(1.7, 9.0), objects=None, method: str = "auto",
                       azimuths: int = 720, step: float | None = None, margin: float = 0.25,
                       progress: bool = False, patches: bool = True) -> Visibility:
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
    """
    if not cell > 0:
        raise ConfigError(f"visibility: cell must be > 0 metres, got {cell}")
    heights = tuple(float(h) for h in eye_heights)
    if not heights:
        raise ConfigError("visibility: eye_heights must name at least one height")
    if method == "auto":
        method = "horizon" if is_heightfield(net) else "rays"
    if method not in ("horizon", "rays"):
        raise ConfigError(f"visibility: method must be 'auto', 'horizon' or 'rays', got {method!r}")
    n = len(net)
    spheres = np.zeros((0, 4)) if objects is None else np.asarray(objects, dtype=np.float64).reshape(-1, 4)
    m = len(spheres)
    origin, shape = _grid_for(net, cell)
    rows, cols = shape
    # bound the work before allocating: (eye points x targets) booleans (a tiny cell asked for TiBs)
    work = ((rows + 1) * (cols + 1) + rows * cols) * len(heights) * (n * (9 if patches else 0) + 2 * m)
    if work > MAX_VISIBILITY_WORK:
        raise ConfigError(f"visibility: a cell of {cell:g} m cuts the course into {rows} x {cols} cells, "
                          f"{work / 2**30:.1f} GiB of eye-target tests (limit {MAX_VISIBILITY_WORK / 2**30:.0f} GiB): "
                          "use a larger visibility.cell")
    ptargets = patch_targets(net) if patches else np.zeros((n, 0, 3))  # (n, 9, 3)
    k = ptargets.shape[1]
    otargets = np.concatenate([spheres[:, :3], spheres[:, :3] + np.stack([np.zeros(m), np.zeros(m), spheres[:, 3]], 1)])
    targets = np.concatenate([ptargets.reshape(-1, 3), otargets])
    xy, zg, hit, nodes = _eye_points(net, origin, shape, cell, heights)
    eyes = np.concatenate([np.column_stack([xy, zg + h]) for h in heights])  # (g * H, 3)
    valid = np.tile(hit, len(heights))
    vis_eye = np.zeros((len(eyes), len(targets)), dtype=bool)
    idx = np.nonzero(valid)[0]
    if method == "horizon":
        lo, hi = net.bounds
        size = float(np.median(net.patch_size))
        st = float(step) if step is not None else max(size / 4.0, 0.25)
        grid = _HeightGrid(net, st, margin)
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
    # per ground point: union over heights; per cell: union over its five ground points
    g = len(xy)
    per_point = vis_eye.reshape(len(heights), g, -1).any(axis=0)  # (g, targets)
    point_valid = valid.reshape(len(heights), g).any(axis=0)
    cells = rows * cols
    cell_vis = np.zeros((cells, len(targets)), dtype=bool)
    cell_ok = np.zeros(cells, dtype=bool)
    for j in range(nodes.shape[1]):
        cell_vis |= per_point[nodes[:, j]]
        cell_ok |= point_valid[nodes[:, j]]
    cell_vis[~cell_ok] = True  # no eye on the terrain: keep everything
    pv = cell_vis[:, : n * k].reshape(cells, n, k).any(axis=2) if k else np.ones((cells, n), dtype=bool)
    ov = cell_vis[:, n * k:].reshape(cells, 2, m).any(axis=1) if m else np.zeros((cells, 0), bool)
    pbits = np.packbits(pv, axis=1, bitorder="little")
    obits = np.packbits(ov, axis=1, bitorder="little") if m else np.zeros((cells, 0), np.uint8)
    return Visibility(origin, float(cell), shape, pbits, obits, n, m, method, heights)


def culling_report(net, vis: Visibility, cameras) -> dict:
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
