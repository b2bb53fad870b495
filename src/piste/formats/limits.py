"""Sanity limits on counts and sizes read from files, checked before anything is allocated.

A small hostile file can declare a huge count (a 288-byte ``.bpt`` asking for 358 GiB, a 1.2 MB
glTF with 200,000 nodes).  Loaders compare every count with the file's own length (a record needs
at least so many bytes) and with the limits here, and refuse with a
:class:`~piste.errors.FormatError` naming the file and field.  The limits are far above anything
the formats are used for (an SSX course has ~3,000 patches, a character < 100 bones).

API
---
check_count(path, field, n, limit, min_bytes_each=0, available=None) -> int
(a glTF's size, GLB chunks, nesting and counts: piste.formats.gltf.schema.precheck_gltf)
MAX_GLTF_ITEMS, MAX_GLTF_NODES, MAX_GLTF_OBJECTS, MAX_GLTF_VALUES, MAX_GLTF_JSON_BYTES, MAX_PATCHES, MAX_HEIGHTFIELD_SAMPLES
"""

from __future__ import annotations

import os
from typing import Any

from piste.errors import FormatError

__all__ = ["check_count", "MAX_GLTF_ITEMS", "MAX_GLTF_NODES", "MAX_GLTF_OBJECTS", "MAX_GLTF_VALUES",
           "MAX_GLTF_JSON_BYTES", "MAX_PATCHES",
           "MAX_HEIGHTFIELD_SAMPLES"]

#: most entries in any top-level glTF array (accessors, meshes, materials, ...)
MAX_GLTF_ITEMS = 1 << 20
#: most glTF nodes (the hierarchy, skins and animations are walked per node)
MAX_GLTF_NODES = 20_000
#: most JSON objects in a glTF document: pygltflib builds a Python object for each (~0.1 ms), so
#: this bounds the parse at a few seconds (RobotExpressive has 2,078; a 200k-node file took 39 s)
MAX_GLTF_OBJECTS = 50_000
#: most JSON values (objects, arrays, numbers, strings) in a glTF document (the walks are linear)
MAX_GLTF_VALUES = 1_000_000
#: largest glTF JSON text (embedded base64 buffers included: a ~48 MB model)
MAX_GLTF_JSON_BYTES = 64 << 20
#: most terrain patches (.bpt, patch nets): the default course has 2,560
MAX_PATCHES = 1 << 20
#: most height-field samples (pixels) decoded and fitted: 4096 x 4096
MAX_HEIGHTFIELD_SAMPLES = 1 << 24


def check_count(path: str | os.PathLike[str], field: str, n: Any, limit: int, min_bytes_each: int = 0, available: int | None = None) -> int:
    """``n`` as an int after checking ``0 <= n <= limit`` and, when ``available`` bytes remain in the
    file, that ``n`` records of at least ``min_bytes_each`` bytes fit in them."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise FormatError(path, f"expected a count >= 0, got {n!r}", field=field)
    if n > limit:
        raise FormatError(path, f"count {n} is more than the limit of {limit}", field=field)
    if available is not None and n * min_bytes_each > available:
        raise FormatError(path, f"count {n} needs at least {n * min_bytes_each} bytes but the file has only "
                                f"{available} left", field=field)
    return n
