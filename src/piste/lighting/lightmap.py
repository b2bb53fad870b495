"""Per-patch light maps: atlas layout, sample points on the exact surface, sampling, the baker.

The talk's "off line lighting": every patch is evaluated as a ``res x res`` grid of points
(``res`` = 8 or 16) on the exact bicubic surface with its exact normal, the full lighting equation
(:func:`piste.lighting.lights.shade`, with terrain self-shadowing) runs at every point, and the
results are stored as one tile per patch in a 2D atlas.  Because the renderer looks lighting up by
the patch parameter ``(u, v)`` (the light-map UVs), the colour at a surface point is the same at
every tessellation level: no LOD light popping.

Atlas conventions
-----------------
* Tile texel ``(i, j)`` (column ``i`` along ``u``, row ``j`` along ``v``) holds the lighting at
  patch parameter ``(i / (res - 1), j / (res - 1))``: texel *centres* sit on the sample points, so
  a bilinear lookup at a sample point returns the sample exactly.
* Each tile is surrounded by ``gutter`` texels that replicate its edge texels (corners too), so
  bilinear filtering at the tile border reads only the tile's own values: no bleeding.
* ``net.lightmap_rect[p] = (u0, v0, u1, v1)``: atlas UV of parameter (0, 0) and (1, 1); the atlas
  UV of ``(u, v)`` is ``(u0 + u (u1 - u0), v0 + v (v1 - v0))``.  Atlas UV ``(s, t)`` addresses
  texel ``(s W - 0.5, t H - 0.5)``; image row ``y`` is ``t = (y + 0.5) / H`` (no flip: upload
  the array as is).
* Layout: tiles of ``res + 2 gutter`` texels in ``ceil(sqrt(n))`` columns, patch ``k`` at column
  ``k % cols``, row ``k // cols`` (the layout of :func:`piste.terrain.net.default_lightmap_rects`).
* Values are linear light, 1.0 = full; 8-bit atlases are half-bright (``texel = round(128 c)``,
  clamped to 255), as on the PS2.

Seams: sample points on a shared edge are the same points in both patches (evaluated once per edge
with the symmetric edge evaluator) and get one normal, the normalised mean of the patches'
normals (at corners: of every patch at the welded corner), while the patches agree within 60
degrees; past 90 degrees (a fold) each keeps its own, smoothly in between (:func:`seam_weight`:
no switch along an edge whose fold angle changes).  The baker then welds the light along every
seam (:func:`weld_seam_light`): both tiles hold the same values, folds included, so no seam shows
a jump and C0-only nets show no crease at seams.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods, FrozenDataMethods
from piste.errors import ValidationError
from piste.scene_data import Lights
from piste.terrain.bezier import eval_edges, grid_params
from piste.terrain.net import PatchNet

__all__ = [
    "weld_seam_light",
    "seam_weight",
    "AtlasLayout",
    "atlas_layout",
    "with_lightmap_layout",
    "lightmap_params",
    "sample_points",
    "lightmap_uv",
    "sample_atlas",
    "assemble_atlas",
    "encode_half_bright",
    "decode_half_bright",
    "LightMap",
]


# --------------------------------------------------------------------------- layout
@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class AtlasLayout(FrozenDataMethods):
    """Where each patch's tile sits in the atlas.

    ``n`` patches, tiles of ``res x res`` texels plus ``gutter`` on each side, ``cols x rows`` cells.
    """

    n: int
    res: int
    gutter: int
    cols: int
    rows: int

    @property
    def cell(self) -> int:
        """Texels per tile including gutters."""
        return self.res + 2 * self.gutter

    @property
    def width(self) -> int:
        return self.cols * self.cell

    @property
    def height(self) -> int:
        return self.rows * self.cell

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)`` of the atlas image."""
        return (self.height, self.width)

    def origins(self) -> np.ndarray:
        """Texel ``(x, y)`` of each tile's first (non-gutter) texel, ``(n, 2)`` int64."""
        k = np.arange(self.n)
        return np.stack([(k % self.cols) * self.cell + self.gutter, (k // self.cols) * self.cell + self.gutter], 1)

    def rects(self) -> np.ndarray:
        """``(u0, v0, u1, v1)`` per patch: atlas UV of parameter (0, 0) and (1, 1) at texel
        centres, ``(n, 4)`` float32."""
        o = self.origins().astype(np.float64)
        x0, y0 = o[:, 0] + 0.5, o[:, 1] + 0.5
        w, h = self.width, self.height
        return np.stack([x0 / w, y0 / h, (x0 + self.res - 1) / w, (y0 + self.res - 1) / h], 1).astype(np.float32)


def atlas_layout(n: int, res: int = 8, gutter: int = 1) -> AtlasLayout:
    """Layout of ``n`` tiles of ``res x res`` texels with ``gutter`` texels around each.

    ``res`` must be at least 2 (the talk uses 8 or 16); ``gutter >= 1`` keeps bilinear filtering
    inside a tile.
    """
    n, res, gutter = int(n), int(res), int(gutter)
    if n < 1:
        raise ValidationError(f"atlas layout: need at least one patch, got {n}")
    if res < 2:
        raise ValidationError(f"atlas layout: res must be >= 2 texels per tile side, got {res}")
    if gutter < 0:
        raise ValidationError(f"atlas layout: gutter must be >= 0, got {gutter}")
    cols = int(math.ceil(math.sqrt(n)))
    rows = int(math.ceil(n / cols))
    return AtlasLayout(n, res, gutter, cols, rows)


def with_lightmap_layout(net: PatchNet, res: int = 8, gutter: int = 1, inplace: bool = False) -> PatchNet:
    """``net`` (or a shallow copy of it) with ``lightmap_rect`` pointing at tiles of ``res``."""
    rects = atlas_layout(len(net), res, gutter).rects()
    target = net if inplace else copy.copy(net)
    target.lightmap_rect = rects
    return target


# --------------------------------------------------------------------------- sample points
def lightmap_params(res: int) -> tuple[np.ndarray, np.ndarray]:
    """Parameters of a tile's texel centres: ``(u, v)`` each ``(res * res,)`` float64, row-major
    with ``u`` fastest (index ``j * res + i`` is ``(i / (res-1), j / (res-1))``)."""
    return grid_params(int(res))


def _side_slots(res: int) -> np.ndarray:
    """Flat tile indices of each side's samples in the side's own direction, ``(4, res)``."""
    t = np.arange(res)
    last = res - 1
    return np.stack([t, t * res + last, last * res + t, t * res])


def _normalize(v: np.ndarray) -> np.ndarray:
    length = np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])
    return v / np.where(length > 0.0, length, 1.0)[..., None]


#: seam normals are averaged fully while two patches' normals are within 60 degrees, not at all
#: beyond 90 degrees (a fold), smoothly in between (cosines); the light itself is then welded
#: along every shared edge (:func:`weld_seam_light`), so no tile pair shows a jump
SEAM_FULL, SEAM_NONE = float(np.cos(np.radians(60.0))), 0.0


def seam_weight(cos_angle: npt.ArrayLike) -> np.ndarray:
    """How much of a neighbour's normal a seam sample takes: 1 while the normals are within 60
    degrees (``cos >= SEAM_FULL``), 0 beyond 90 degrees, a smoothstep between."""
    x = np.clip((np.asarray(cos_angle, dtype=np.float64) - SEAM_NONE) / (SEAM_FULL - SEAM_NONE), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def sample_points(net: PatchNet, res: int, smooth_seams: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Light-map sample points of every patch on the exact surface, with normals.

    Parameters
    ----------
    net : PatchNet
    res : samples per tile side
    smooth_seams : share points and normals along shared edges and corners (see module docstring);
        False gives each patch's own exact normals

    Returns
    -------
    positions (n, res*res, 3) float64, normals (n, res*res, 3) float64 (unit).  Sample ``j*res + i``
    is parameter ``(i/(res-1), j/(res-1))``.
    """
    u, v = lightmap_params(res)
    pos, nrm = net.evaluate(u, v)
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    nrm = np.ascontiguousarray(nrm, dtype=np.float64)
    if not smooth_seams:
        return pos, nrm
    n = len(net)
    own_nrm = nrm.copy()
    slots = _side_slots(res)  # (4, res)
    # positions on every side: the edge curve evaluated once, in canonical order, flipped per side
    epts = eval_edges(np.asarray(net.edge_cp, dtype=np.float64), res, interior=False)  # (e, res, 3)
    se = np.asarray(net.side_edge)
    sf = np.asarray(net.side_flip)
    side_pts = epts[se]  # (n, 4, res, 3) canonical order
    side_pts = np.where(sf[:, :, None, None], side_pts[:, :, ::-1], side_pts)
    pidx = np.arange(n)[:, None, None]
    pos[pidx, slots[None]] = side_pts

    # normals along shared edges: mean of both patches' normals in canonical order
    shared = np.asarray(net.shared_edges)
    if len(shared):
        pa, pb = net.edge_patches[shared, 0], net.edge_patches[shared, 1]
        sa, sb = net.edge_sides[shared, 0], net.edge_sides[shared, 1]
        na = nrm[pa[:, None], slots[sa]]  # (s, res, 3) side order
        nb = nrm[pb[:, None], slots[sb]]
        fa, fb = sf[pa, sa], sf[pb, sb]
        na = np.where(fa[:, None, None], na[:, ::-1], na)
        nb = np.where(fb[:, None, None], nb[:, ::-1], nb)
        # average only where right: fully (one normal for both: bit-identical light) while the two
        # normals are within SEAM_FULL of each other, not at all past SEAM_NONE (a real fold keeps
        # its crease), and smoothly in between, so no jump runs along an edge whose fold angle
        # changes along it (the old all-or-nothing rule at 90 degrees switched mid-edge)
        w = seam_weight((na * nb).sum(-1))[..., None]
        for p, s, f, own, other in ((pa, sa, fa, na, nb), (pb, sb, fb, nb, na)):
            m = np.where(w >= 1.0, _normalize(na + nb), _normalize(own + w * other))
            m = np.where(f[:, None, None], m[:, ::-1], m)
            nrm[p[:, None], slots[s]] = m

    # normals at welded corners: mean over every patch touching the corner
    corner_slot = np.array([0, res - 1, res * res - 1, (res - 1) * res])  # c0..c3
    cid = np.asarray(net.corner_ids).ravel()  # (n*4,)
    cn = own_nrm[:, corner_slot].reshape(-1, 3)
    # each patch's corner: the mean of the corner's normals weighted by how well they agree with
    # its own (seam_weight), so patches on one side of a fold share a normal, the fold stays sharp
    order = np.argsort(cid, kind="stable")
    out = cn.copy()
    starts = np.flatnonzero(np.r_[True, cid[order][1:] != cid[order][:-1]])
    ends = np.r_[starts[1:], len(order)]
    for a, b in zip(starts, ends):
        if b - a < 2:
            continue
        g = order[a:b]
        wts = seam_weight(cn[g] @ cn[g].T)  # (k, k), 1 on the diagonal
        out[g] = _normalize(wts @ cn[g])
        full = (wts >= 1.0).all()
        if full:  # all agree: one normal, bit-identical in every tile
            out[g] = _normalize(cn[g].sum(0))[None]
    nrm[:, corner_slot] = out.reshape(n, 4, 3)
    return pos, nrm


def weld_seam_light(net: PatchNet, tiles: npt.ArrayLike) -> np.ndarray:
    """Light ``tiles (n, res, res, C)`` with every shared edge's samples set to the mean of both
    patches' values and every welded corner's to the mean over its patches, so the two tiles of a
    seam hold the same light even across a fold (where the normals are not averaged and each side
    is lit by its own): no jump at the seam, the crease spread over one texel each side.  Samples
    that already agree (smooth seams: one shared normal) are unchanged.  Returns a new array."""
    t = np.array(tiles, dtype=np.float32, copy=True)
    n, res = t.shape[0], t.shape[1]
    flat = t.reshape(n, res * res, -1)
    slots = _side_slots(res)
    sf = np.asarray(net.side_flip)
    shared = np.asarray(net.shared_edges)
    if len(shared):
        pa, pb = net.edge_patches[shared, 0], net.edge_patches[shared, 1]
        sa, sb = net.edge_sides[shared, 0], net.edge_sides[shared, 1]
        fa, fb = sf[pa, sa], sf[pb, sb]
        la = flat[pa[:, None], slots[sa]]
        lb = flat[pb[:, None], slots[sb]]
        la = np.where(fa[:, None, None], la[:, ::-1], la)
        lb = np.where(fb[:, None, None], lb[:, ::-1], lb)
        mean = 0.5 * (la + lb)
        for p, s_, f in ((pa, sa, fa), (pb, sb, fb)):
            flat[p[:, None], slots[s_]] = np.where(f[:, None, None], mean[:, ::-1], mean)
    corner_slot = np.array([0, res - 1, res * res - 1, (res - 1) * res])
    cid = np.asarray(net.corner_ids).ravel()
    cl = flat[:, corner_slot].reshape(n * 4, -1).astype(np.float64)
    total = np.zeros((int(cid.max()) + 1, cl.shape[1]))
    np.add.at(total, cid, cl)
    count = np.bincount(cid, minlength=len(total))[:, None]
    flat[:, corner_slot] = (total / np.maximum(count, 1))[cid].reshape(n, 4, -1).astype(np.float32)
    return t


# --------------------------------------------------------------------------- atlas sampling
def lightmap_uv(rects: npt.ArrayLike, patch: npt.ArrayLike, u: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray:
    """Atlas UV of patch parameters: ``rects (n, 4)``, ``patch (k,)`` int, ``u, v (k,)`` ->
    ``(k, 2)`` float64."""
    r = np.asarray(rects, dtype=np.float64)[np.asarray(patch)]
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    return np.stack([r[..., 0] + u * (r[..., 2] - r[..., 0]), r[..., 1] + v * (r[..., 3] - r[..., 1])], -1)


def sample_atlas(atlas: npt.ArrayLike, uv: npt.ArrayLike, mode: str = "bilinear") -> np.ndarray:
    """Sample an atlas like a GPU texture unit with clamp-to-edge addressing.

    Parameters
    ----------
    atlas : (H, W) or (H, W, C) array (any numeric dtype; values are returned unscaled)
    uv : (..., 2) float atlas coordinates; texel ``(x, y)`` has its centre at
        ``((x + 0.5) / W, (y + 0.5) / H)``
    mode : "bilinear" (GL_LINEAR) or "point" (GL_NEAREST)

    Returns
    -------
    (..., C) float64 (``(...)`` for a 2D atlas).
    """
    a = np.asarray(atlas)
    flat = a.ndim == 2
    if flat:
        a = a[..., None]
    h, w = a.shape[:2]
    uv = np.asarray(uv, dtype=np.float64)
    x = uv[..., 0] * w
    y = uv[..., 1] * h
    if mode == "point":
        xi = np.clip(np.floor(x).astype(np.int64), 0, w - 1)
        yi = np.clip(np.floor(y).astype(np.int64), 0, h - 1)
        out = a[yi, xi].astype(np.float64)
    elif mode == "bilinear":
        x = x - 0.5
        y = y - 0.5
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx = (x - x0)[..., None]
        fy = (y - y0)[..., None]
        x0 = x0.astype(np.int64)
        y0 = y0.astype(np.int64)
        xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
        ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
        a = a.astype(np.float64, copy=False)
        top = a[ya, xa] * (1.0 - fx) + a[ya, xb] * fx
        bottom = a[yb, xa] * (1.0 - fx) + a[yb, xb] * fx
        out = top * (1.0 - fy) + bottom * fy
    else:
        raise ValidationError(f"sample_atlas: mode must be 'bilinear' or 'point', got {mode!r}")
    return out[..., 0] if flat else out


def assemble_atlas(tiles: npt.ArrayLike, layout: AtlasLayout, fill: float = 0.0) -> np.ndarray:
    """Place tiles into an atlas and replicate each tile's edge texels into its gutter.

    Parameters
    ----------
    tiles : (n, res, res, C) array, ``tiles[p, j, i]`` = parameter ``(i/(res-1), j/(res-1))``
    layout : AtlasLayout for ``n`` and ``res``
    fill : value of the unused cells

    Returns
    -------
    (H, W, C) array of ``tiles.dtype``.
    """
    tiles = np.asarray(tiles)
    n, res = layout.n, layout.res
    if tiles.shape[:3] != (n, res, res):
        raise ValidationError(f"assemble_atlas: expected tiles of shape ({n}, {res}, {res}, C), got {tiles.shape}")
    g, cell = layout.gutter, layout.cell
    padded = np.pad(tiles, ((0, 0), (g, g), (g, g), (0, 0)), mode="edge")
    cells = np.full((layout.rows * layout.cols, cell, cell, tiles.shape[3]), fill, dtype=tiles.dtype)
    cells[:n] = padded
    return np.ascontiguousarray(
        cells.reshape(layout.rows, layout.cols, cell, cell, -1).transpose(0, 2, 1, 3, 4).reshape(layout.height, layout.width, -1)
    )


def encode_half_bright(colors: npt.ArrayLike) -> np.ndarray:
    """Linear light (1.0 = full) to the PS2's half-bright 8 bits: ``round(128 c)`` clamped to
    [0, 255] (over-bright up to 255/128 ~ 1.99 survives)."""
    c = np.asarray(colors, dtype=np.float64)
    return np.clip(np.rint(c * 128.0), 0, 255).astype(np.uint8)


def decode_half_bright(texels: npt.ArrayLike) -> np.ndarray:
    """Half-bright 8-bit texels to linear light (``texel / 128``), float32."""
    return (np.asarray(texels, dtype=np.float32) / np.float32(128.0)).astype(np.float32)


# --------------------------------------------------------------------------- the result
@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class LightMap(DataMethods):
    """A baked light-map atlas.

    Attributes
    ----------
    atlas : (H, W, 3) float32 linear light (1.0 = full), gutters filled
    rects : (n, 4) float32 ``lightmap_rect`` of each patch (set it on the net: :meth:`apply`)
    res, gutter : tile size and gutter in texels
    manifest : dict describing the bake (inputs hash, lights, statistics)
    """

    atlas: np.ndarray
    rects: np.ndarray
    res: int
    gutter: int = 1
    manifest: dict = field(default_factory=dict)

    @property
    def layout(self) -> AtlasLayout:
        return atlas_layout(len(self.rects), self.res, self.gutter)

    def to_uint8(self) -> np.ndarray:
        """The atlas as half-bright 8-bit RGB (128 = 1.0), ``(H, W, 3)`` uint8."""
        return encode_half_bright(self.atlas)

    def tiles(self) -> np.ndarray:
        """The tiles without gutters, ``(n, res, res, 3)`` float32."""
        lay = self.layout
        o = lay.origins()
        r = np.arange(self.res)
        return self.atlas[o[:, 1, None, None] + r[None, :, None], o[:, 0, None, None] + r[None, None, :]]

    def sample(self, patch: npt.ArrayLike, u: np.ndarray, v: np.ndarray, mode: str = "bilinear") -> np.ndarray:
        """Lighting at patch parameters from the atlas: ``patch, u, v (k,)`` -> ``(k, 3)`` float64."""
        return sample_atlas(self.atlas, lightmap_uv(self.rects, patch, u, v), mode)

    def apply(self, net: PatchNet, inplace: bool = False) -> PatchNet:
        """``net`` (or a shallow copy) with ``lightmap_rect`` set to this atlas's tiles."""
        if len(net) != len(self.rects):
            raise ValidationError(f"light map has {len(self.rects)} tiles, the net {len(net)} patches")
        target = net if inplace else copy.copy(net)
        target.lightmap_rect = self.rects.copy()
        return target


def inputs_key(net: PatchNet, lights: Lights, res: int, gutter: int, shadows: bool, chunk_size: int, version: str,
               extra: dict[str, Any] | None = None) -> str:
    """SHA-256 over everything that determines a bake's output (hex).  ``extra``: further settings
    (bounces, the area sun), hashed only when given, so the keys of plain bakes do not change."""
    import hashlib  # here: a bundle render never bakes, so it never loads hashlib (OpenSSL)

    h = hashlib.sha256()
    h.update(version.encode())
    cp = np.ascontiguousarray(net.control_points, dtype="<f8")
    h.update(str(cp.shape).encode())
    h.update(cp.tobytes())
    h.update(json.dumps(lights.to_dict(), sort_keys=True).encode())
    h.update(json.dumps([int(res), int(gutter), bool(shadows), int(chunk_size)]).encode())
    if extra:
        h.update(json.dumps(extra, sort_keys=True).encode())
    return h.hexdigest()
