"""Synthetic SSX Tricky levels (the tests' golden files; no retail data): a PatchNet's patches
written as a ``.pbd`` / ``.ssh`` / ``_L.ssh`` set by piste's own encoder
(:mod:`piste.formats.ssx.synth`).

A synthetic level is a hilly slope of ``rows x cols`` patches (or any PatchNet), its shared
boundaries perturbed by a fraction of a game unit (the game's seams are near-equal, not equal),
a few 8-bit and 4-bit indexed textures, and light-map pages lit by a fixed sun with ``Cs``/``As``
computed the game's way against each patch's base texture reduced to 8x8.  The same input gives
the same bytes.

API
---
make_level(net=None, rows=2, cols=3, seed=0, jitter=0.02, ...) -> SynthLevel
SynthLevel.write(folder, name="SYNTH") -> Path of NAME.pbd (NAME.ssh and NAME_L.ssh beside it)
synthetic_net(rows, cols, seed, patch_size=12.0) -> PatchNet (metres)
synthetic_pages(pbd, textures, sun, ambient, seed) -> (P, 128, 128, 4) uint8
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from piste.formats.ssx.lightmap import base_tiles, reduce_texture, tile_params
from piste.formats.ssx.pbd import GAME_SCALE, Pbd, parse_pbd, records_from_arrays, records_from_net, write_pbd
from piste.formats.ssx.ssh import SshBank, lightmap_bank, place_tiles, write_ssh
from piste.formats.ssx.synth import pbd_bytes, synthetic_textures
from piste.terrain.bezier import evaluate
from piste.terrain.net import PatchNet

__all__ = ["make_level", "SynthLevel", "synthetic_net", "synthetic_pages"]


def synthetic_net(rows: int = 2, cols: int = 3, seed: int = 0, patch_size: float = 12.0) -> PatchNet:
    """A C0 hilly slope of ``rows x cols`` patches in metres (falling towards -y), as a PatchNet."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.arange(3 * cols + 1), np.arange(3 * rows + 1))
    step = patch_size / 3.0
    x, y = gx * step, gy * step
    z = 0.35 * y + 1.5 * np.sin(x / (1.7 * patch_size) + rng.uniform(0, 6)) * np.cos(y / (1.3 * patch_size))
    z += rng.normal(0.0, 0.15, z.shape)
    return PatchNet.from_control_grid(np.stack([x, y, z], axis=-1), name="synthetic")


def synthetic_pages(pbd: Pbd, textures: SshBank, sun: tuple[float, float, float] | np.ndarray = (-0.45, -0.35, 0.82),
                    ambient: float = 0.45, seed: int = 0) -> np.ndarray:
    """Light-map pages for ``pbd``: a Lambertian sun plus ambient (some over-bright), encoded the
    game's way (As = max CL, Cs = Cd - Cd CL / As against the 8x8-reduced base texture), placed
    at each patch's stored rect and page, transposed.  ``(P, 128, 128, 4) uint8``."""
    u, v = tile_params()
    _, nrm = evaluate(pbd.control_points, u, v)
    s = np.asarray(sun, np.float64)
    s /= np.linalg.norm(s)
    light = ambient + 1.1 * np.clip(nrm @ s, 0, None)  # (n, 64) up to ~1.55: over-bright
    tint = np.array([1.0, 0.96, 0.9])
    cl = np.clip(np.rint(light[..., None] * tint * 128.0), 0, 255).astype(np.int64)  # half-bright CL
    red = np.stack([reduce_texture(im.rgba()) for im in textures.images])
    cd = base_tiles(red, pbd.texture_index, pbd.uv).reshape(len(pbd), 64, 3).astype(np.int64)
    a = cl.max(axis=-1)
    d = (2 * cd * cl + np.maximum(a, 1)[..., None]) // (2 * np.maximum(a, 1)[..., None])  # round(cd cl / as)
    cs = np.clip(cd - np.minimum(d, cd), 0, 255)
    tiles = np.concatenate([cs, a[..., None]], axis=-1).astype(np.uint8).reshape(len(pbd), 8, 8, 4)
    n_pages = int(pbd.lightmap_page.max()) + 1 if len(pbd) else 0
    return place_tiles(tiles, pbd.lightmap_rect, pbd.lightmap_page, n_pages)


@dataclass
class SynthLevel:
    """A synthetic level: ``pbd`` (parsed from its own bytes), ``textures`` and ``lightmaps`` banks."""

    pbd: Pbd
    textures: SshBank
    lightmaps: SshBank

    def write(self, folder: str | Path, name: str = "SYNTH") -> Path:
        """Write ``NAME.pbd``, ``NAME.ssh`` and ``NAME_L.ssh`` into ``folder``; returns the .pbd path."""
        folder = Path(folder)
        path = folder / f"{name}.pbd"
        write_pbd(self.pbd, path)
        write_ssh(self.textures, folder / f"{name}.ssh")
        write_ssh(self.lightmaps, folder / f"{name}_L.ssh")
        self.pbd.path = path
        return path


def make_level(net: PatchNet | None = None, rows: int = 2, cols: int = 3, seed: int = 0, jitter: float = 0.02, n_textures: int = 3,
               trick_every: int = 0, platform: int = 1, patch_size: float = 12.0) -> SynthLevel:
    """Build a synthetic level.

    Parameters
    ----------
    net : PatchNet in metres (default :func:`synthetic_net` of ``rows x cols`` patches)
    jitter : game units of noise added to every patch's own boundary control points (near-equal
        seams, as in retail levels); 0 keeps shared boundaries exactly equal
    n_textures : textures in the bank; patch ``k`` uses texture ``k % n_textures``
    trick_every : every ``trick_every``-th patch is trick-only (0: none)
    """
    if net is None:
        net = synthetic_net(rows, cols, seed, patch_size)
    n = len(net)
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    trick = (k % trick_every == trick_every - 1) if trick_every else np.zeros(n, bool)
    surface = np.where(k % 5 == 4, 5, 1).astype(np.uint32)
    rec = records_from_net(net, GAME_SCALE, texture_index=(k % max(n_textures, 1)).astype(np.int16),
                           surface_type=surface, trick_only=trick)
    if jitter:
        cp = np.asarray(net.control_points) / GAME_SCALE
        mask = np.zeros((4, 4), bool)
        mask[[0, 3], :] = mask[:, [0, 3]] = True
        cp = cp + rng.uniform(-jitter, jitter, cp.shape) * mask[None, :, :, None]
        geo = records_from_arrays(cp)
        for f in ("power", "aabb_min", "aabb_max", "corners"):
            rec[f] = geo[f]
    # UVs inset like the game's tiles
    inset = np.float32(0.008)
    rec["uv"][:, :, :2] = np.array([(0, 0), (1, 0), (0, 1), (1, 1)], np.float32) * (1 - 2 * inset) + inset
    data = pbd_bytes(rec, n_textures, platform)
    pbd = parse_pbd(data)
    textures = synthetic_textures(n_textures, seed=seed)
    pages = synthetic_pages(pbd, textures, seed=seed)
    return SynthLevel(pbd, textures, lightmap_bank(pages))
