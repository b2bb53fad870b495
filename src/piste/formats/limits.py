"""Sanity limits on counts and sizes read from files, checked before anything is allocated.

A small hostile file can declare a huge count (a 288-byte ``.bpt`` asking for 358 GiB, a 1.2 MB
glTF with 200,000 nodes).  Loaders compare every count with the file's own length (a record needs
at least so many bytes) and with the limits here, and refuse with a
:class:`~piste.errors.FormatError` naming the file and field.  The limits are far above anything
the formats are used for (an SSX course has ~3,000 patches, a character < 100 bones).

API
---
precheck_gltf(path) -> dict        size, GLB chunk layout, JSON nesting and array counts of a glTF
check_count(path, field, n, limit, min_bytes_each=0, available=None) -> int
MAX_GLTF_ITEMS, MAX_GLTF_NODES, MAX_GLTF_OBJECTS, MAX_GLTF_VALUES, MAX_GLTF_JSON_BYTES, MAX_PATCHES, MAX_HEIGHTFIELD_SAMPLES
"""

from __future__ import annotations

import struct
from pathlib import Path

from piste.errors import FormatError
from piste.formats import safe_io
from piste.formats.gltf_schema import check_gltf_types

__all__ = ["precheck_gltf", "check_count", "MAX_GLTF_ITEMS", "MAX_GLTF_NODES", "MAX_GLTF_OBJECTS", "MAX_GLTF_VALUES",
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

_GLTF_ARRAYS = ("accessors", "animations", "bufferViews", "buffers", "cameras", "images", "materials", "meshes",
                "nodes", "samplers", "scenes", "skins", "textures")


def check_count(path, field: str, n, limit: int, min_bytes_each: int = 0, available: int | None = None) -> int:
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


def _count_values(doc, stop_objects: int, stop_values: int) -> tuple[int, int]:
    """``(objects, values)`` in JSON ``doc``; counting stops past either limit (iterative)."""
    n_obj, n_val, stack = 0, 0, [doc]
    while stack and n_obj <= stop_objects and n_val <= stop_values:
        v = stack.pop()
        if isinstance(v, dict):
            n_obj += 1
            n_val += len(v)
            stack.extend(x for x in v.values() if isinstance(x, (dict, list)))
        elif isinstance(v, list):
            n_val += len(v)
            if n_val <= stop_values:
                stack.extend(x for x in v if isinstance(x, (dict, list)))
    return n_obj, n_val


def precheck_gltf(path) -> dict:
    """Check a ``.gltf`` / ``.glb`` before a full parser sees it; returns its JSON document.

    Refuses non-regular files and files over ``safe_io.MAX_MODEL_BYTES``, GLB headers and chunk
    lengths that disagree with the file, JSON nested deeper than ``safe_io.MAX_JSON_DEPTH``,
    top-level arrays longer than ``MAX_GLTF_ITEMS`` (``MAX_GLTF_NODES`` for nodes), and fields of
    the wrong JSON type (:mod:`piste.formats.gltf_schema`).
    """
    path = Path(path)
    data = safe_io.read_regular(path, safe_io.MAX_MODEL_BYTES, what="model file")
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise FormatError(path, f"GLB file of {len(data)} bytes is shorter than its 20-byte header")
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise FormatError(path, f"GLB version {version}: expected 2", field="header.version")
        if length > len(data):
            raise FormatError(path, f"GLB header declares {length} bytes but the file has {len(data)}",
                              field="header.length")
        clen, ctype = struct.unpack_from("<II", data, 12)
        if ctype != 0x4E4F534A:
            raise FormatError(path, "the first GLB chunk is not JSON", field="chunk0.type")
        if 20 + clen > length:
            raise FormatError(path, f"JSON chunk of {clen} bytes runs past the end of the file ({length} bytes)",
                              field="chunk0.length")
        text = data[20:20 + clen]
    else:
        text = data
    if len(text) > MAX_GLTF_JSON_BYTES:
        raise FormatError(path, f"JSON of {len(text)} bytes is more than the limit of {MAX_GLTF_JSON_BYTES} (keep "
                                "large buffers in .bin files or a .glb)")
    doc = safe_io.loads_json(text, path)
    if not isinstance(doc, dict):
        raise FormatError(path, f"expected a JSON object at the top level, got {type(doc).__name__}")
    for key in _GLTF_ARRAYS:
        v = doc.get(key)
        if isinstance(v, list):
            check_count(path, key, len(v), MAX_GLTF_NODES if key == "nodes" else MAX_GLTF_ITEMS)
    n_objects, n_values = _count_values(doc, MAX_GLTF_OBJECTS, MAX_GLTF_VALUES)
    if n_objects > MAX_GLTF_OBJECTS or n_values > MAX_GLTF_VALUES:
        raise FormatError(path, f"more than {MAX_GLTF_OBJECTS} JSON objects or {MAX_GLTF_VALUES} values (a glTF "
                                "this large would take minutes to parse)")
    check_gltf_types(doc, path)  # every field piste reads has its specified JSON type
    return doc
