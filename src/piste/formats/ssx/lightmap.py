"""The game's light-map texels: ``As`` and ``Cs`` against each patch's base texture reduced to 8x8.

Facts (``/work/shared/SSX-FORMATS.md``): a light-map texel holds ``A = As = max(CL.r, CL.g, CL.b)``
(128 = 1.0, over-bright up to 255) and ``RGB = Cs = Cd - Cd CL / As`` computed against the
patch's base texture downsampled to 8x8; the GS then blends ``(Cd - Cs) As >> 7``.

Pure numpy (no lighting or rendering): the light itself comes from elsewhere (the baker).

API
---
::

    reduce_texture(rgba) -> (8, 8, 3) uint8                 box filter to 8x8 (rows = texture v)
    base_tiles(reduced, texture_index, uv) -> (n, 8, 8, 3)  each patch's Cd at its light-map texel
                                                           centres (u, v) = ((i + .5) / 8, (j + .5) / 8)
    gs_blend(cd, cs, as_) -> uint8                          ((Cd - Cs) As) >> 7, clamped
    light_from_source(cd, cs, as_) -> float32               the linear light CL the texels encode
    tile_params() -> (u, v)                                 texel-centre parameters, index j * 8 + i
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from piste.errors import ValidationError

__all__ = ["reduce_texture", "base_tiles", "gs_blend", "light_from_source", "tile_params", "TILE"]

TILE = 8


def tile_params() -> tuple[np.ndarray, np.ndarray]:
    """Edge-aligned texel centres of an 8x8 tile: ``(u, v)`` each ``(64,)``, index ``j * 8 + i``
    is ``((i + 0.5) / 8, (j + 0.5) / 8)``."""
    t = (np.arange(TILE) + 0.5) / TILE
    return np.tile(t, TILE), np.repeat(t, TILE)


def reduce_texture(rgba: npt.ArrayLike) -> np.ndarray:
    """An image ``(h, w, 3|4) uint8`` box-filtered to ``(8, 8, 3) uint8`` (rounded means;
    sides that are not multiples of 8 are resampled by nearest texel first)."""
    img = np.asarray(rgba)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValidationError(f"reduce_texture: expected (h, w, 3|4) uint8, got {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    hh, ww = max(TILE, -(-h // TILE) * TILE), max(TILE, -(-w // TILE) * TILE)
    if (hh, ww) != (h, w):
        img = img[(np.arange(hh) * h // hh)][:, (np.arange(ww) * w // ww)]
    rgb = img[..., :3].astype(np.float64).reshape(TILE, hh // TILE, TILE, ww // TILE, 3).mean(axis=(1, 3))
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)


def base_tiles(reduced: npt.ArrayLike, texture_index: npt.ArrayLike, uv: npt.ArrayLike) -> np.ndarray:
    """Each patch's base colour at its light-map texel centres.

    Parameters
    ----------
    reduced : (T, 8, 8, 3) uint8 textures reduced to 8x8 (:func:`reduce_texture`), rows = v
    texture_index : (n,) int, index into ``reduced`` (out-of-range indices use white)
    uv : (n, 4, 2) corner UVs in the SSX order (u0,v0), (u1,v0), (u0,v1), (u1,v1)

    Returns
    -------
    (n, 8, 8, 3) uint8, ``[k, j, i]`` at patch parameter ``((i + .5) / 8, (j + .5) / 8)``: the
    reduced texture's texel under the bilinear UV (nearest, wrapped).
    """
    red = np.asarray(reduced, dtype=np.uint8)
    ti = np.asarray(texture_index, dtype=np.int64)
    uv = np.asarray(uv, dtype=np.float64)
    n = len(ti)
    u, v = tile_params()
    w00, w10, w01, w11 = (1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v
    tex = (w00[None, :, None] * uv[:, None, 0] + w10[None, :, None] * uv[:, None, 1]
           + w01[None, :, None] * uv[:, None, 2] + w11[None, :, None] * uv[:, None, 3])  # (n, 64, 2)
    s = np.floor(tex[..., 0] * TILE).astype(np.int64) % TILE
    t = np.floor(tex[..., 1] * TILE).astype(np.int64) % TILE
    ok = (ti >= 0) & (ti < len(red))
    out = np.full((n, TILE * TILE, 3), 255, np.uint8)
    if ok.any():
        out[ok] = red[ti[ok][:, None], t[ok], s[ok]]
    return out.reshape(n, TILE, TILE, 3)


def gs_blend(cd: npt.ArrayLike, cs: npt.ArrayLike, as_: npt.ArrayLike) -> np.ndarray:
    """The GS's light-map blend ``((Cd - Cs) As) >> 7`` clamped to 0..255: ``cd, cs (..., 3)``,
    ``as_ (...)`` -> ``(..., 3) uint8``."""
    cd = np.asarray(cd).astype(np.int32)
    cs = np.asarray(cs).astype(np.int32)
    a = np.asarray(as_).astype(np.int32)[..., None]
    return np.clip(((cd - cs) * a) >> 7, 0, 255).astype(np.uint8)


def light_from_source(cd: npt.ArrayLike, cs: npt.ArrayLike, as_: npt.ArrayLike) -> np.ndarray:
    """The linear light (1.0 = full) that stored ``Cs, As`` give on base colour ``Cd``:
    ``(Cd - Cs) As / 128 / Cd`` (``As / 128`` where ``Cd = 0``), ``(..., 3) float32``."""
    cd = np.asarray(cd, dtype=np.float64)
    cs = np.asarray(cs, dtype=np.float64)
    a = np.asarray(as_, dtype=np.float64)[..., None] / 128.0
    with np.errstate(divide="ignore", invalid="ignore"):
        cl = np.where(cd > 0, np.maximum(cd - cs, 0.0) * a / np.maximum(cd, 1.0), a)
    return cl.astype(np.float32)
