"""Textures the renderer makes itself: a procedural snow base texture and a placeholder light map.

Light-map atlas convention (shared with the light-map baker): an atlas is an ``(H, W, 3|4) uint8``
image whose element ``[y, x]`` is the texel at texture coordinate ``((x + 0.5) / W, (y + 0.5) / H)``
(row 0 is ``v = 0``; no vertical flip).  Patch ``k``'s tile is ``net.lightmap_rect[k] = (u0, v0,
u1, v1)``: patch parameter ``(0, 0)`` samples the centre of texel ``(u0 W - 0.5, v0 H - 0.5)`` and
``(1, 1)`` the centre of ``(u1 W - 0.5, v1 H - 0.5)``.

API
---
::

    snow_texture             (N, N, 4) uint8 tileable procedural snow
    placeholder_lightmap     (H, W, 4) uint8 atlas lit by a fixed sun from the surface normals
                             (a stand-in until baked light maps exist)
    lightmap_atlas_size      (W, H) of the atlas a net's ``lightmap_rect`` describes
    track_field              (H, W) float32 signed distance across a track (metres), a projected texture
    light_texels             (H, W, 3) float16 light-map texels as the terrain pass uploads them
    mip_chain                the mip levels of an (H, W, C) uint8 image, as Mesa's glGenerateMipmap makes them
    mipmapped_texture        a moderngl texture with its mip levels computed on the CPU and uploaded
    MipLevels                a render target's mip levels redrawn on the GPU by piste's own shader
    LOD_COLORS               debug colours of 4x4, 6x6, 8x8 and glue patches
"""

from __future__ import annotations

import ctypes
from functools import lru_cache
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from piste.errors import RenderError, ValidationError
from piste.formats.ziplite import read_npz
from piste.render.context import load_shader
from piste.terrain.bezier import grid_params

if TYPE_CHECKING:
    import moderngl

    from piste.terrain.net import PatchNet

__all__ = ["snow_texture", "compute_snow_texture", "SNOW_FILE", "placeholder_lightmap", "lightmap_atlas_size",
           "track_field", "track_texels", "TRACK_TEXEL", "TRACK_CLIP", "light_texels", "light_texels_in_range", "LIGHT_CLIP", "mip_chain",
           "mipmapped_texture", "MipLevels", "LOD_COLORS", "SUN_DIRECTION"]

#: debug colours (RGB uint8) by patch kind: 4x4 green, 6x6 yellow, 8x8 red, glue (non-uniform) blue
LOD_COLORS = {
    4: (70, 190, 90),
    6: (235, 200, 60),
    8: (220, 70, 60),
    0: (70, 120, 230),
}
#: the placeholder light map's sun: from the south-west, 40 degrees up (unit vector towards the sun)
SUN_DIRECTION = np.array([-0.55, -0.45, 0.70]) / np.linalg.norm([-0.55, -0.45, 0.70])


def _periodic_noise(n: int, rng: np.random.Generator, beta: float, lo: int, hi: int) -> np.ndarray:
    """Tileable noise ``(n, n) float64`` in [-1, 1] with a power spectrum ~ 1/f^beta between
    frequencies ``lo`` and ``hi`` (cycles per tile); periodic by construction (built in Fourier space)."""
    f = np.fft.fftfreq(n) * n
    # the amplitude depends on |f| only (even), so the noise is real: half spectra (rfft2/irfft2),
    # half the work of fft2/ifft2 of the full spectrum, the same texture (2 ms less at start-up)
    fr = np.hypot(f[:, None], f[None, : n // 2 + 1])
    amp = np.where((fr >= lo) & (fr <= hi), np.maximum(fr, 1.0) ** (-beta / 2.0), 0.0)
    out = np.fft.irfft2(np.fft.rfft2(rng.standard_normal((n, n))) * amp, s=(n, n))
    return out / max(np.abs(out).max(), 1e-12)


#: the default snow texture (size 256, seed 0) exactly as :func:`snow_texture` computes it, shipped with
#: the package: in a fresh process the first FFT (numpy.fft's import and plans) cost the first frame
#: 70-180 ms on a loaded 2-core machine; ``tests/render/test_texture_data.py`` checks the file against the code
SNOW_FILE = Path(__file__).resolve().parents[1] / "data" / "snow_256.npz"


@lru_cache(maxsize=1)
def _stored_snow() -> np.ndarray | None:
    """:data:`SNOW_FILE`'s texture (read-only), or None when it is missing or not a (256, 256, 4) uint8."""
    try:  # (read without zipfile: piste.formats.ziplite)
        a = read_npz(SNOW_FILE)["snow"]
    except (OSError, KeyError, ValueError):
        return None
    if a.shape != (256, 256, 4) or a.dtype != np.uint8:
        return None
    a.flags.writeable = False
    return a


def snow_texture(size: int = 256, seed: int = 0) -> np.ndarray:
    """A tileable snow texture: soft drifts, fine grain and a few sparkles.

    Returns ``(size, size, 4) uint8`` RGBA (alpha 255).  Deterministic for a seed.  The default
    (256, seed 0) is read from :data:`SNOW_FILE` (the same bytes), any other computed.
    """
    if size < 8 or size & (size - 1):
        raise ValidationError(f"snow_texture: size must be a power of two >= 8, got {size}")
    if size == 256 and seed == 0:
        stored = _stored_snow()
        if stored is not None:
            return stored.copy()
    return compute_snow_texture(size, seed)


def compute_snow_texture(size: int = 256, seed: int = 0) -> np.ndarray:
    """:func:`snow_texture` always computed (the reference :data:`SNOW_FILE` is checked against)."""
    if size < 8 or size & (size - 1):
        raise ValidationError(f"snow_texture: size must be a power of two >= 8, got {size}")
    rng = np.random.default_rng(seed)
    drifts = _periodic_noise(size, rng, 3.0, 1, size // 8)
    grain = _periodic_noise(size, rng, 1.0, size // 16, size // 2)
    sparkle = rng.random((size, size)) > 0.997
    lum = 0.90 + 0.05 * drifts + 0.025 * grain + 0.06 * sparkle
    tint = np.array([0.97, 0.985, 1.0])  # snow is faintly blue
    rgb = np.clip(lum[..., None] * tint, 0.0, 1.0)
    out = np.empty((size, size, 4), dtype=np.uint8)
    out[..., :3] = np.round(rgb * 255.0)
    out[..., 3] = 255
    return out


def lightmap_atlas_size(net: PatchNet, res: int = 8) -> tuple[int, int]:
    """``(W, H)`` of the atlas described by ``net.lightmap_rect`` for tiles of ``res x res`` texels.

    A tile spans ``res - 1`` texels between its first and last texel centres, so
    ``W = (res - 1) / (u1 - u0)``.
    """
    rect = np.asarray(net.lightmap_rect, dtype=np.float64)
    du, dv = rect[:, 2] - rect[:, 0], rect[:, 3] - rect[:, 1]
    if (du <= 0).any() or (dv <= 0).any():
        k = int(np.nonzero((du <= 0) | (dv <= 0))[0][0])
        raise ValidationError(f"{net.name}: lightmap_rect of patch {k} is {rect[k].tolist()}: expected u1 > u0, v1 > v0")
    w = np.round((res - 1) / du)
    h = np.round((res - 1) / dv)
    if (w != w[0]).any() or (h != h[0]).any():
        raise ValidationError(f"{net.name}: lightmap_rect tiles are not all {res}x{res} texels of one atlas")
    return int(w[0]), int(h[0])


def placeholder_lightmap(net: PatchNet, res: int = 8, sun: npt.ArrayLike = SUN_DIRECTION, gutter: int = 1) -> np.ndarray:
    """PLACEHOLDER light map: each patch's tile shaded from its surface normals by a fixed sun.

    Not a baked light map (no shadows, no bounce): it stands in until ``piste.lighting`` bakes one.
    Normals are evaluated on each patch's ``res x res`` tile grid and shaded with a sky ambient plus
    a Lambertian sun; tiles are laid out with ``net.lightmap_rect`` and their border texels copied
    into ``gutter`` texels around them so bilinear filtering never bleeds between tiles.

    Returns ``(H, W, 4) uint8`` (alpha 255), see the module docstring for the layout.
    """
    W, H = lightmap_atlas_size(net, res)
    u, v = grid_params(res)  # index j*res + i is (u_i, v_j)
    _, nrm = net.evaluate(u, v)  # (n, res*res, 3)
    n = len(nrm)
    nrm = nrm.reshape(n, res, res, 3)  # [k, j (v), i (u)]
    sun = np.asarray(sun, dtype=np.float64)
    sun = sun / np.linalg.norm(sun)
    ndl = np.clip(nrm @ sun, 0.0, 1.0)
    sky = 0.5 + 0.5 * np.clip(nrm[..., 2], -1.0, 1.0)  # hemisphere ambient: up-facing sees the sky
    amb = np.array([0.36, 0.40, 0.48])
    sun_col = np.array([0.72, 0.68, 0.60])
    rgb = sky[..., None] * amb + ndl[..., None] * sun_col
    tiles = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)  # (n, res, res, 3)
    g = int(gutter)
    if g:
        tiles = np.pad(tiles, ((0, 0), (g, g), (g, g), (0, 0)), mode="edge")
    rect = np.asarray(net.lightmap_rect, dtype=np.float64)
    x0 = np.round(rect[:, 0] * W - 0.5).astype(np.int64) - g
    y0 = np.round(rect[:, 1] * H - 0.5).astype(np.int64) - g
    t = res + 2 * g
    xs = x0[:, None, None] + np.arange(t)[None, None, :]  # (n, 1, t)
    ys = y0[:, None, None] + np.arange(t)[None, :, None]  # (n, t, 1)
    xs, ys = np.broadcast_arrays(xs, ys)
    ok = (xs >= 0) & (xs < W) & (ys >= 0) & (ys < H)
    atlas = np.zeros((H, W, 4), dtype=np.uint8)
    atlas[..., 3] = 255
    atlas[ys[ok], xs[ok], :3] = tiles[ok]
    # tile interiors win over neighbours' gutters: write them last
    if g:
        inner = np.zeros((t, t), dtype=bool)
        inner[g:-g, g:-g] = True
        sel = ok & inner[None]
        atlas[ys[sel], xs[sel], :3] = tiles[sel]
    return atlas


#: the track field's grid spacing in metres (:func:`track_field`'s default; a bundle stores it with the field)
TRACK_TEXEL = 0.75
#: metres across the track beyond which the uploaded field is clipped (:func:`track_texels`)
TRACK_CLIP = 1000.0
#: ``TRACK_CLIP`` as float16 bits: a float16 field whose magnitudes' bits are all at most this is in range
_TRACK_CLIP_BITS = int(np.array(TRACK_CLIP, np.float16).view(np.uint16))


def track_texels(field: npt.ArrayLike) -> np.ndarray:
    """The track field as the terrain pass uploads it: ``(H, W) float16``, clipped to
    +-:data:`TRACK_CLIP` metres (NaN stays NaN).  A float16 field already in range (what a bundle
    stores: this function's result at build time) is returned as it is, checked on its bits (numpy's
    float16 reductions cost ~15 ms at the default course's 1334 x 534 texels, this ~0.3 ms)."""
    f = np.asarray(field)
    if f.dtype == np.float16 and f.ndim == 2 and f.size and \
            int((f.view(np.uint16) & np.uint16(0x7FFF)).max()) <= _TRACK_CLIP_BITS:
        return f
    return np.clip(np.asarray(field, dtype=np.float32), -TRACK_CLIP, TRACK_CLIP).astype(np.float16)


#: the brightest light-map texel the terrain pass uploads (half floats; brighter is clipped: :func:`light_texels`)
LIGHT_CLIP = 65000.0
#: ``LIGHT_CLIP`` as float16 bits: a float16 atlas whose bits are all at most this is in [+0, LIGHT_CLIP]
LIGHT_CLIP_BITS = int(np.array(LIGHT_CLIP, np.float16).view(np.uint16))


def light_texels_in_range(texels: np.ndarray) -> bool:
    """Whether every float16 texel is in ``[-0, LIGHT_CLIP]`` (no NaN, inf nor negative value),
    judged on its bits (``-0.0``, which a clip of ``-0.0`` keeps, is ``0x8000``)."""
    v = texels.view(np.uint16)
    return not v.size or int(v.max()) <= LIGHT_CLIP_BITS or not bool(((v > LIGHT_CLIP_BITS) & (v != 0x8000)).any())


def light_texels(atlas: npt.ArrayLike) -> np.ndarray:
    """A float light-map atlas ``(H, W, 3|4)`` (linear light) as the terrain pass uploads it:
    ``(H, W, 3) float16``, its RGB clipped to ``[0, LIGHT_CLIP]``.  A float16 ``(H, W, 3)`` atlas
    already in range (what a bundle stores: this function's result at build time, ``lightmap/texels``)
    is returned as it is, checked on its bits (~0.3 ms; numpy's float16 min/max cost ~15 ms).
    RenderError when a texel is NaN or infinite."""
    a = np.asarray(atlas)
    if a.dtype == np.float16 and a.ndim == 3 and a.shape[2] == 3 and a.size and light_texels_in_range(a):
        return a
    # min/max (NaN and inf show in them) instead of isfinite + a clip of every texel: ~1 ms less
    lo, hi = (float(a.min()), float(a.max())) if a.size else (0.0, 0.0)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise RenderError("light-map atlas: values must be finite")
    rgb = a[..., :3] if 0.0 <= lo and hi <= LIGHT_CLIP else np.clip(a[..., :3], 0.0, LIGHT_CLIP)
    return rgb.astype(np.float16)


def track_field(centerline: npt.ArrayLike, bounds: tuple[npt.ArrayLike, npt.ArrayLike], texel: float = TRACK_TEXEL) -> tuple[np.ndarray, np.ndarray]:
    """Signed horizontal distance (metres) from the track's centre line, sampled on a world x-y grid.

    Parameters
    ----------
    centerline : (k, 3) float, points down the track
    bounds : ((3,), (3,)) world box the field covers (e.g. ``net.bounds``)
    texel : grid spacing in metres

    Returns
    -------
    field : (H, W) float32, row ``y`` / column ``x`` at world ``(x0 + (x + 0.5) texel, y0 + (y + 0.5) texel)``,
        positive to the right of the direction of travel
    rect : (4,) float64 ``(x0, y0, x1, y1)`` the world rectangle the texture spans
    """
    pts = np.asarray(centerline, dtype=np.float64)[:, :2]
    if pts.ndim != 2 or len(pts) < 2:
        raise ValidationError(f"track_field: centerline must have shape (k>=2, 3), got {np.shape(centerline)}")
    lo, hi = (np.asarray(b, dtype=np.float64)[:2] for b in bounds)
    w = max(int(np.ceil((hi[0] - lo[0]) / texel)), 2)
    h = max(int(np.ceil((hi[1] - lo[1]) / texel)), 2)
    xs = lo[0] + (np.arange(w) + 0.5) * texel
    ys = lo[1] + (np.arange(h) + 0.5) * texel
    dy = np.diff(pts[:, 1])
    if (dy > 0).all() or (dy < 0).all():
        # the usual course: the line runs monotonically down y, so x_c(y) is a function and the
        # distance across is (x - x_c(y)) cos(heading)
        order = np.argsort(pts[:, 1])
        xc = np.interp(ys, pts[order, 1], pts[order, 0])
        slope = np.gradient(xc, ys)
        # (x - x_c) / sqrt(1 + slope^2), negated for a line running down y, in float64 and rounded to
        # float32: a band of rows at a time through one small float64 buffer (the same bits as the
        # whole (h, w) float64 field, without a fresh process's page faults on 5.7 MB of it)
        scale = np.sqrt(1.0 + slope * slope)
        field = np.empty((h, w), np.float32)
        rows = max(1, (1 << 16) // w)
        buf = np.empty((rows, w))
        for r in range(0, h, rows):
            t = buf[:min(rows, h - r)]
            np.subtract(xs[None, :], xc[r:r + rows, None], out=t)
            t /= scale[r:r + rows, None]
            if dy[0] < 0:
                np.negative(t, out=t)
            field[r:r + len(t)] = t
        rect = np.array([lo[0], lo[1], lo[0] + w * texel, lo[1] + h * texel])
        return field, rect
    # any other line: nearest point of the densely resampled line by k-d tree, side by the tangent
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, cum[-1], max(int(cum[-1] / (0.5 * texel)), 2))
    dense = np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)
    tangent = np.gradient(dense, axis=0)
    from scipy.spatial import cKDTree

    gx, gy = np.meshgrid(xs, ys)
    q = np.stack([gx.ravel(), gy.ravel()], axis=1)
    dist, idx = cKDTree(dense).query(q, workers=-1)
    rel = q - dense[idx]
    side = np.sign(rel[:, 0] * tangent[idx, 1] - rel[:, 1] * tangent[idx, 0])
    field = (dist * np.where(side == 0, 1.0, side)).reshape(h, w).astype(np.float32)
    rect = np.array([lo[0], lo[1], lo[0] + w * texel, lo[1] + h * texel])
    return field, rect


def mip_chain(image: npt.ArrayLike) -> list[np.ndarray]:
    """The mip levels of ``image`` ``(H, W, C) uint8`` (H and W powers of two) down to 1 x 1.

    Returns ``[image, level 1, ..., level n]``, level ``l`` of shape ``(max(H >> l, 1), max(W >> l,
    1), C) uint8``.  Each texel is the mean of its 2 x 2 (2 x 1 once an axis is 1 texel) parent
    texels the way Mesa's ``glGenerateMipmap`` computes it on llvmpipe (a bilinear sample at the
    corner the four share): the horizontal pairs averaged and rounded half up to 8 bits, then those
    averaged vertically, likewise (bit-identical to llvmpipe's levels; other drivers' rounding may
    differ by one step).  Precomputed on the CPU as the PS2 did: no GPU work at load.
    """
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[..., None]
    if img.dtype != np.uint8 or img.ndim != 3:
        raise ValidationError(f"mip_chain: expected an (H, W, C) uint8 image, got {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    if h < 1 or w < 1 or h & (h - 1) or w & (w - 1):
        raise ValidationError(f"mip_chain: image sides must be powers of two, got {w} x {h}")
    out = [img]
    lv: np.ndarray = img.astype(np.uint16)
    while lv.shape[0] > 1 or lv.shape[1] > 1:
        if lv.shape[1] > 1:
            lv = (lv[:, 0::2] + lv[:, 1::2] + 1) >> 1
        if lv.shape[0] > 1:
            lv = (lv[0::2] + lv[1::2] + 1) >> 1
        out.append(lv.astype(np.uint8))
    return out


# GL enums (OpenGL 3.3 core)
_GL_TEXTURE_2D, _GL_UNSIGNED_BYTE, _GL_UNPACK_ALIGNMENT = 0x0DE1, 0x1401, 0x0CF5
_GL_TEXTURE_BASE_LEVEL, _GL_TEXTURE_MAX_LEVEL = 0x813C, 0x813D
#: components -> (internal format, format) of moderngl's uint8 textures: R8, RG8, RGB8, RGBA8
_GL_FORMATS = {1: (0x8229, 0x1903), 2: (0x822B, 0x8227), 3: (0x8051, 0x1907), 4: (0x8058, 0x1908)}


def _find_library(name: str) -> str | None:
    """``ctypes.util.find_library(name)``; ctypes.util (and the subprocess module it imports, ~3 ms
    of a fresh process's start) is imported only where the usual library names were not found."""
    import ctypes.util

    return ctypes.util.find_library(name)


@lru_cache(maxsize=None)
def _gl_entry_points() -> SimpleNamespace | None:
    """``glTexImage2D``, ``glTexParameteri``, ``glPixelStorei`` and ``glFramebufferTexture2D`` (a
    namespace) from the system's GL dispatch library (libglvnd's ``libOpenGL.so.0``, else
    ``libGL``), which call into the context current on this thread, as moderngl's own calls do;
    None where there is no such library (then textures build their mip levels with
    ``build_mipmaps``)."""
    names = ("libOpenGL.so.0", "libGL.so.1", lambda: _find_library("OpenGL"),
             lambda: _find_library("GL"))  # (find_library runs ldconfig: only if needed)
    u, i = ctypes.c_uint, ctypes.c_int
    signatures = {"glTexImage2D": [u, i, i, i, i, i, u, u, ctypes.c_void_p], "glTexParameteri": [u, u, i],
                  "glPixelStorei": [u, i], "glFramebufferTexture2D": [u, u, u, u, i]}
    name: Any
    for name in names:
        name = name() if callable(name) else name
        if not name:
            continue
        try:
            lib = ctypes.CDLL(name)
            fns = {f: getattr(lib, f) for f in signatures}
        except (OSError, AttributeError):
            continue
        for f, args in signatures.items():
            fns[f].argtypes = args
            fns[f].restype = None
        return SimpleNamespace(**fns)
    return None


def mipmapped_texture(ctx: moderngl.Context, image: npt.ArrayLike, cpu: bool = True) -> moderngl.Texture:
    """A moderngl texture of ``image`` ``(H, W, C) uint8`` (C = 1..4) with a full mip chain.

    The levels are :func:`mip_chain`'s, uploaded level by level (``glTexImage2D``: moderngl 5
    allocates mip levels only in ``build_mipmaps``, whose ``glGenerateMipmap`` makes Mesa compile
    a blit shader for the first texture of each kind in a process, 70-180 ms on llvmpipe, at every
    start).  Falls back to ``build_mipmaps`` (the GPU's filter: identical on llvmpipe) for sides that
    are not powers of two, where no GL dispatch library is found, or with ``cpu=False``.  The
    texture's filter is left at moderngl's default; callers set theirs.  (moderngl does not know
    of the uploaded levels: ``Texture.read(level=l > 0)`` refuses; sample them instead.)
    """
    img = np.ascontiguousarray(image)
    if img.ndim == 2:
        img = img[..., None]
    if img.dtype != np.uint8 or img.ndim != 3 or not 1 <= img.shape[2] <= 4:
        raise RenderError(f"texture: expected an (H, W, 1..4) uint8 image, got {img.shape} {img.dtype}")
    h, w, c = img.shape
    tex = ctx.texture((w, h), c, img.tobytes(), alignment=1)
    gl = _gl_entry_points() if cpu else None
    if gl is None or h & (h - 1) or w & (w - 1):
        tex.build_mipmaps()
        return tex
    internal, fmt = _GL_FORMATS[c]
    levels = mip_chain(img)
    tex.use(ctx.default_texture_unit)  # bound where moderngl binds the textures it writes
    gl.glPixelStorei(_GL_UNPACK_ALIGNMENT, 1)
    for level, lv in enumerate(levels[1:], start=1):
        lv = np.ascontiguousarray(lv)
        gl.glTexImage2D(_GL_TEXTURE_2D, level, internal, lv.shape[1], lv.shape[0], 0, fmt, _GL_UNSIGNED_BYTE,
                        lv.ctypes.data)
    gl.glTexParameteri(_GL_TEXTURE_2D, _GL_TEXTURE_BASE_LEVEL, 0)
    gl.glTexParameteri(_GL_TEXTURE_2D, _GL_TEXTURE_MAX_LEVEL, len(levels) - 1)
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise RenderError(f"uploading a {w}x{h} texture's mip levels: OpenGL error {err}")
    return tex


_GL_FRAMEBUFFER, _GL_COLOR_ATTACHMENT0 = 0x8D40, 0x8CE0


class MipLevels:
    """Mip levels 1 to ``levels`` of an RGBA8 render target, redrawn from level 0 on the GPU by
    :meth:`build` with piste's own shader (``mip_level.frag.glsl``: the same 2 x 2 means as
    :func:`mip_chain` and llvmpipe's ``glGenerateMipmap``).  The target (``texture``) has sides that
    halve exactly ``levels`` times (even, or 1, down to level ``levels - 1``; 384 x 128 for 4 levels).

    Why not ``build_mipmaps``: Mesa's ``glGenerateMipmap`` draws with an internal blit shader
    that llvmpipe compiles in every process (70-110 ms at the first call: its disk cache keeps only
    GLSL programs), while this program comes from the shader cache after the first run.  Each
    level is drawn into a framebuffer holding that level (``glFramebufferTexture2D``; moderngl 5
    attaches only level 0) while the texture's base and max level are the level above, so the
    draw never samples the level it writes.  ``build`` leaves blending, depth test and face
    culling disabled and re-binds the framebuffer and viewport it found.

    ``MipLevels.supported(ctx, texture, levels)``: whether the texture's sides halve exactly and
    this machine's GL library gives the entry points (else use ``build_mipmaps``).
    """

    def __init__(self, ctx: moderngl.Context, texture: moderngl.Texture, levels: int) -> None:
        w, h = texture.size
        gl = _gl_entry_points()
        if gl is None:
            raise RenderError("MipLevels: no GL library with glFramebufferTexture2D (use build_mipmaps)")
        self.levels = max(0, min(int(levels), int(np.log2(max(w, h)))))
        if not self.supported(ctx, texture, self.levels):
            raise RenderError(f"MipLevels: expected an RGBA8 texture whose sides halve exactly {self.levels} "
                              f"times, got {w} x {h} x {texture.components} {texture.dtype}")
        self.ctx, self.texture, self._gl = ctx, texture, gl
        self.sizes = [(max(w >> lv, 1), max(h >> lv, 1)) for lv in range(self.levels + 1)]
        internal, fmt = _GL_FORMATS[4]
        texture.use(ctx.default_texture_unit)
        for lv in range(1, self.levels + 1):  # allocate the levels (contents undefined until build)
            gl.glTexImage2D(_GL_TEXTURE_2D, lv, internal, *self.sizes[lv], 0, fmt, _GL_UNSIGNED_BYTE, None)
        self._limits(0, self.levels)
        # the program is compiled at the first build (where ComputeMips draws the levels this one
        # never builds: ~3 ms of llvmpipe compiling in a fresh process with an empty shader cache)
        self._prog: Any = None  # moderngl types prog["name"] as a union: read as Any
        self._vao: Any = None
        self.fbo = ctx.framebuffer(color_attachments=[texture])
        err = ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"MipLevels: allocating {self.levels} levels of a {w}x{h} texture: OpenGL error {err}")

    @property
    def prog(self) -> Any:
        """The program that draws a level from the one above (compiled on first use)."""
        if self._prog is None:
            self._prog = self.ctx.program(vertex_shader=load_shader("fullscreen.vert.glsl"),
                                          fragment_shader=load_shader("mip_level.frag.glsl"))
        return self._prog

    @property
    def vao(self) -> Any:
        """Its vertex array (no buffers: a full-screen triangle from gl_VertexID)."""
        if self._vao is None:
            self._vao = self.ctx.vertex_array(self.prog, [])
        return self._vao

    @staticmethod
    def supported(ctx: moderngl.Context, texture: moderngl.Texture, levels: int) -> bool:
        """Whether :class:`MipLevels` can draw ``levels`` levels of ``texture`` here (else use
        ``build_mipmaps``)."""
        w, h = texture.size
        exact = all(max(s >> lv, 1) == 1 or (s >> lv) % 2 == 0 for s in (w, h) for lv in range(int(levels)))
        return _gl_entry_points() is not None and exact and texture.components == 4 and texture.dtype == "f1"

    def _limits(self, base: int, top: int) -> None:
        self._gl.glTexParameteri(_GL_TEXTURE_2D, _GL_TEXTURE_BASE_LEVEL, base)
        self._gl.glTexParameteri(_GL_TEXTURE_2D, _GL_TEXTURE_MAX_LEVEL, top)

    def build(self) -> None:
        """Redraw levels ``1 .. levels`` from level 0 (what was drawn into the texture)."""
        import moderngl

        if self.levels == 0:
            return
        ctx, gl, tex = self.ctx, self._gl, self.texture
        prev, viewport = ctx.fbo, ctx.viewport
        ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        unit = ctx.default_texture_unit
        self.prog["u_src"].value = unit
        try:
            for lv in range(1, self.levels + 1):
                self.fbo.use()
                gl.glFramebufferTexture2D(_GL_FRAMEBUFFER, _GL_COLOR_ATTACHMENT0, _GL_TEXTURE_2D, tex.glo, lv)
                ctx.viewport = (0, 0, *self.sizes[lv])
                tex.use(unit)
                self._limits(lv - 1, lv - 1)  # sample only the level above
                self.vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            tex.use(unit)
            self._limits(0, self.levels)
            self.fbo.use()
            gl.glFramebufferTexture2D(_GL_FRAMEBUFFER, _GL_COLOR_ATTACHMENT0, _GL_TEXTURE_2D, tex.glo, 0)
            if prev is not None:
                prev.use()
            ctx.viewport = viewport

    def release(self) -> None:
        for obj in (self.fbo, self._vao, self._prog):
            if obj is not None:
                obj.release()
