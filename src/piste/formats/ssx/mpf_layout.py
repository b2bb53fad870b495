"""SSX Tricky ``.mpf`` layout facts shared by the reader/writer (:mod:`piste.formats.ssx.mpf`) and
the conversion to piste's models (:mod:`piste.formats.ssx.mpf_model`): record dtypes, the game's
limits and fixed-point scales, and the strip rule. See :mod:`piste.formats.ssx.mpf` for the sources.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "FORMAT_TRICKY_PS2", "MAX_CHUNK_VERTICES", "MAX_SHADOW_CHUNK_VERTICES", "ENCODER_CHUNK_VERTICES",
    "LOD_TRIANGLE_BUDGETS", "MAX_GROUP_MATRICES", "UV_SCALE", "NORMAL_SCALE", "MORPH_SCALE",
    "SLOT_TRANSFORM_BASE", "SLOT_NORMAL_BASE", "GROUP_RENDER", "GROUP_SHADOW", "GROUP_MORPH", "PALETTE_CONST",
    "MAX_VERTICES_READ", "MAX_FILE_BYTES", "DIR_DTYPE", "BONE_DTYPE", "MATERIAL_DTYPE", "IK_DTYPE", "GROUP_DTYPE",
    "LINK_DTYPE", "MESH_DTYPE", "REF_DTYPE", "PALHDR_DTYPE", "PALETTE_ENTRY_DTYPE", "strip_triangles",
]

FORMAT_TRICKY_PS2 = 8
#: most vertices in a render/morph chunk of a retail model (moby_body.mpf: 59, board.mpf: 57)
MAX_CHUNK_VERTICES = 59
#: most vertices in a shadow chunk (group type 17) of a retail model (moby_body.mpf's BodyShdw750: 165)
MAX_SHADOW_CHUNK_VERTICES = 165
#: what piste's encoder packs a chunk to (below the retail maximum, leaving the VU memory headroom)
ENCODER_CHUNK_VERTICES = 55
#: the talk's triangle budget of each LOD tier (sub-model name suffix): ~3,000 / 1,500 / 750
LOD_TRIANGLE_BUDGETS = {"3000": 3000, "1500": 1500, "750": 750}
MAX_GROUP_MATRICES = 25
UV_SCALE = 4096.0
NORMAL_SCALE = 32768.0
MORPH_SCALE = 12.8  # stored i8 units per model unit
SLOT_TRANSFORM_BASE = 14
SLOT_NORMAL_BASE = 114
GROUP_RENDER, GROUP_SHADOW, GROUP_MORPH = 1, 17, 256
PALETTE_CONST = 36
MAX_VERTICES_READ = 4096  # per chunk; retail holds <= 165, a hostile count is refused
MAX_FILE_BYTES = 64 << 20

DIR_DTYPE = np.dtype([("name", "S16"), ("offset", "<u4"), ("size", "<u4"), ("sections", "<u4", (7,)),
                      ("unused8", "V8"), ("counts", "<i2", (7,)), ("file_id", "i1"), ("pad", "V1"),
                      ("unused4", "V4")])
BONE_DTYPE = np.dtype([("name", "S16"), ("parent_file", "<i2"), ("parent_bone", "<i2"), ("flags", "<i2"),
                       ("mirror", "<i2"), ("translation", "<f4", (3,)), ("rotation", "<f4", (3,)),
                       ("mirror_offset", "<f4", (3,)), ("mirror_scale", "<f4", (6,))])
MATERIAL_DTYPE = np.dtype([("textures", "V4", (5,)), ("blend", "<f4"), ("unused", "<f4", (2,))])
IK_DTYPE = np.dtype([("position", "<f4", (3,)), ("bone", "<u4")])
GROUP_DTYPE = np.dtype([("type", "<u4"), ("material", "<u4"), ("unknown", "<u4"), ("link_count", "<u4"),
                        ("link_offset", "<u4")])
LINK_DTYPE = np.dtype([("offset", "<u4"), ("count", "<u4")])
MESH_DTYPE = np.dtype([("mesh_offset", "<u4"), ("morph_offset", "<u4"), ("morph_size", "<u4")])
REF_DTYPE = np.dtype([("count", "<u4"), ("offset", "<u4")])
PALHDR_DTYPE = np.dtype([("count", "<u4"), ("offset", "<u4"), ("const", "<u4")])
PALETTE_ENTRY_DTYPE = np.dtype([("weight", "<i2"), ("bone", "u1"), ("file", "u1")])
assert DIR_DTYPE.itemsize == 80 and BONE_DTYPE.itemsize == 84 and MATERIAL_DTYPE.itemsize == 32


def strip_triangles(strip_lengths: npt.ArrayLike) -> np.ndarray:
    """Chunk-local triangles ``(t, 3) int64`` of consecutive strips of the given lengths: in a
    strip, triangle ``i`` is ``(i, i+1, i+2)`` for even ``i`` and ``(i+1, i, i+2)`` for odd ``i``."""
    n = np.asarray(strip_lengths, dtype=np.int64).reshape(-1)
    n = n[n >= 3]
    if n.size == 0:
        return np.zeros((0, 3), np.int64)
    starts = np.concatenate([[0], np.cumsum(np.asarray(strip_lengths, np.int64))])[:-1][
        np.asarray(strip_lengths, np.int64) >= 3]
    ntri = n - 2
    local = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    a = np.repeat(starts, ntri) + local
    odd = (local % 2) == 1
    return np.stack([np.where(odd, a + 1, a), np.where(odd, a, a + 1), a + 2], axis=1)
