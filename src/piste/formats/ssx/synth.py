"""piste's own SSX Tricky level encoder: the bytes of a whole ``.pbd`` and synthetic texture banks,
built from the fact sheet (no retail data).  The synthetic levels made of them (a PatchNet's
patches, lit light-map pages) are :mod:`piste.pipeline.ssx_synth`: this module takes and returns
arrays and banks only, and imports no terrain code.

Nothing is invented: every section :func:`pbd_bytes` writes is either given by the caller (the
bytes of a source level) or the **minimal default**, an empty section (count 0, length 0) at its
16-byte aligned place after the patches; the patch records' compiler residue is 0.  The same
input gives the same bytes.

API
---
synthetic_textures(count) -> SshBank
pbd_bytes(records, textures=1, platform=1, sections=None) -> bytes
"""

from __future__ import annotations

import struct

import numpy as np

from piste.formats.ssx.pbd import COUNT_NAMES, HEADER_SIZE, OFFSET_NAMES, VERSION
from piste.formats.ssx.ssh import SshBank, SshImage

__all__ = ["synthetic_textures", "pbd_bytes"]

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
