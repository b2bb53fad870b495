"""piste's own SSX Tricky level encoder: synthetic ``.pbd`` / ``.ssh`` / ``_L.ssh`` sets built from
the fact sheet (the tests' golden files; no retail data).

A synthetic level is a hilly slope of ``rows x cols`` patches (or any PatchNet), its shared
boundaries perturbed by a fraction of a game unit (the game's seams are near-equal, not equal),
a few 8-bit and 4-bit indexed textures, and light-map pages lit by a fixed sun with ``Cs``/``As``
computed the game's way against each patch's base texture reduced to 8x8.

Nothing is invented: every section :func:`pbd_bytes` writes is either given by the caller (the
bytes of a source level) or the **minimal default**, an empty section (count 0, length 0) at its
16-byte aligned place after the patches; the patch records' compiler residue is 0.  The same
input gives the same bytes.

API
---
make_level(net=None, rows=2, cols=3, seed=0, jitter=0.02, ...) -> SynthLevel
SynthLevel.write(folder, name="SYNTH") -> Path of NAME.pbd (NAME.ssh and NAME_L.ssh beside it)
synthetic_net(rows, cols, seed, patch_size=12.0) -> PatchNet (metres)
synthetic_textures(count) -> SshBank
pbd_bytes(records, textures=1, platform=1, sections=None) -> bytes
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from piste.formats.ssx.lightmap import base_tiles, reduce_texture, tile_params
from piste.formats.ssx.pbd import (
    COUNT_NAMES, GAME_SCALE, HEADER_SIZE, OFFSET_NAMES, VERSION, Pbd, parse_pbd, records_from_arrays,
    records_from_net, write_pbd,
)
from piste.formats.ssx.ssh import SshBank, SshImage, lightmap_bank, place_tiles, write_ssh
from piste.terrain.bezier import evaluate
from piste.terrain.net import PatchNet

__all__ = ["make_level", "SynthLevel", "synthetic_net", "synthetic_textures", "pbd_bytes", "synthetic_pages"]

#: the sections after the patches, in file order: (offset name, count name or None)
_SECTIONS = (
    ("player_starts", "player_starts"), ("instances", "instances"), ("particle_instances", "particle_instances"),
    ("materials", "materials"), ("material_blocks", "material_blocks"), ("lights", "lights"),
    ("splines", "splines"), ("spline_segments", "spline_segments"), ("flipbooks", "flipbooks"),
    ("model_pointers", None), ("models", "models"), ("particle_model_pointers", None),
    ("particle_models", "particle_models"), ("camera_pointers", None), ("cameras", "cameras"), ("hash", None),
    ("mesh_data", None),
)


def pbd_bytes(records: np.ndarray, textures: int = 1, platform: int = 1, sections: dict | None = None) -> bytes:
    """A whole ``.pbd``: the header, the patches at 0x90, then every other section 16-byte aligned.

    ``sections`` maps an offset name (:data:`~piste.formats.ssx.pbd.OFFSET_NAMES`) to ``(count,
    bytes)`` (``count`` None for the pointer tables, hash and mesh data, which have no count).
    A section not given is the minimal default: empty, count 0 (player starts: offset 0, as the
    game leaves them).  No byte is made up.
    """
    counts = dict.fromkeys(COUNT_NAMES, 0)
    offsets = dict.fromkeys(OFFSET_NAMES, 0)
    counts["patches"] = len(records)
    counts["textures"] = int(textures)
    body = bytearray(b"\0" * (0x90 - HEADER_SIZE))
    pos = 0x90
    offsets["patches"] = pos
    body += records.tobytes()
    pos += records.nbytes
    for name, cname in _SECTIONS:
        pad = -pos % 16
        body += b"\0" * pad
        pos += pad
        count, blob = (sections or {}).get(name, (0, b""))
        if cname is not None:
            counts[cname] = int(count or 0)
        offsets[name] = pos if name != "player_starts" or blob else 0  # the game leaves player starts unused
        body += blob
        pos += len(blob)
    head = VERSION + bytes([platform]) + struct.pack("<15I", *counts.values()) + struct.pack("<18I", *offsets.values())
    return head + bytes(body)


def synthetic_net(rows: int = 2, cols: int = 3, seed: int = 0, patch_size: float = 12.0):
    """A C0 hilly slope of ``rows x cols`` patches in metres (falling towards -y), as a PatchNet."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.arange(3 * cols + 1), np.arange(3 * rows + 1))
    step = patch_size / 3.0
    x, y = gx * step, gy * step
    z = 0.35 * y + 1.5 * np.sin(x / (1.7 * patch_size) + rng.uniform(0, 6)) * np.cos(y / (1.3 * patch_size))
    z += rng.normal(0.0, 0.15, z.shape)
    return PatchNet.from_control_grid(np.stack([x, y, z], axis=-1), name="synthetic")


def synthetic_textures(count: int = 3, size: int = 32, seed: int = 0) -> SshBank:
    """``count`` textures: 8-bit indexed snow, rock and 4-bit ice (repeating), stored the game's
    way: half-bright colours and alpha (128 = 1.0), an empty long name."""
    rng = np.random.default_rng(seed + 7)
    tints = [(236, 240, 250), (120, 110, 100), (180, 215, 240), (230, 205, 150)]
    images = []
    yy, xx = np.mgrid[0:size, 0:size]
    for t in range(count):
        four_bit = t % 3 == 2
        k = 16 if four_bit else 256
        base = np.array(tints[t % len(tints)], np.float64)
        ramp = np.linspace(0.55, 1.0, k)[:, None]
        pal = np.empty((k, 4), np.uint8)
        pal[:, :3] = (np.clip(np.rint(base * ramp), 0, 255).astype(np.int64) + 1) // 2  # stored half-bright
        pal[:, 3] = 0x80
        pattern = 0.5 + 0.25 * np.sin(2 * np.pi * (xx + 2 * yy * (t + 1)) / size) + 0.25 * rng.random((size, size))
        idx = np.clip((pattern * (k - 1)).astype(np.int64), 0, k - 1).astype(np.uint8)
        images.append(SshImage(f"{t:04d}", 1 if four_bit else 2, idx, pal, long_name=""))
    return SshBank(images)


def synthetic_pages(pbd: Pbd, textures: SshBank, sun=(-0.45, -0.35, 0.82), ambient=0.45, seed: int = 0) -> np.ndarray:
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

    def write(self, folder, name: str = "SYNTH") -> Path:
        """Write ``NAME.pbd``, ``NAME.ssh`` and ``NAME_L.ssh`` into ``folder``; returns the .pbd path."""
        folder = Path(folder)
        path = folder / f"{name}.pbd"
        write_pbd(self.pbd, path)
        write_ssh(self.textures, folder / f"{name}.ssh")
        write_ssh(self.lightmaps, folder / f"{name}_L.ssh")
        self.pbd.path = path
        return path


def make_level(net=None, rows: int = 2, cols: int = 3, seed: int = 0, jitter: float = 0.02, n_textures: int = 3,
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
