"""The types of every glTF 2.0 field piste reads, checked on the JSON before pygltflib sees it.

pygltflib keeps whatever the JSON holds: a ``"scenes": "red"`` or a ``"mesh": true`` reached the
loader as a string or a bool and ended in a raw ``AttributeError`` / ``TypeError``.  This module
walks the document once against a small schema (the glTF 2.0 specification's types: objects,
arrays, non-negative integer indices, finite numbers, strings, booleans, fixed-length number
arrays) and raises :class:`~piste.errors.FormatError` naming the file and the field
(``nodes[3].mesh: expected an index (integer >= 0), got true``).  Unknown keys, ``extras`` and
extensions other than those piste reads are not checked (the specification allows anything there).

API
---
check_gltf_types(doc, path)     FormatError on the first field of the wrong type
precheck_gltf(path) -> dict     size, GLB chunk layout, JSON nesting and array counts, then the types
"""

from __future__ import annotations

import math
import os
import struct
from pathlib import Path
from typing import Any

from piste.errors import FormatError
from piste.formats import limits, safe_io

__all__ = ["check_gltf_types", "precheck_gltf"]

_GLTF_ARRAYS = ("accessors", "animations", "bufferViews", "buffers", "cameras", "images", "materials", "meshes",
                "nodes", "samplers", "scenes", "skins", "textures")

# leaf types
IDX = "index"  # integer >= 0
UINT = "uint"  # integer >= 0 (counts, offsets, lengths)
POS = "count"  # integer >= 1
INT = "int"
NUM = "number"  # finite
STR = "string"
BOOL = "bool"
ANY = "any"


#: a schema: a kind name (IDX, NUM, ...) or a nested ("array" | "object", ...) tuple
Schema = Any


def arr(item: Schema, n: int | None = None) -> tuple[str, Schema, int | None]:
    return ("array", item, n)


def obj(**fields: Schema) -> tuple[str, dict[str, Schema]]:
    return ("object", fields)


TEXINFO = obj(index=IDX, texCoord=UINT, scale=NUM, strength=NUM, extensions=obj(
    KHR_texture_transform=obj(offset=arr(NUM, 2), rotation=NUM, scale=arr(NUM, 2), texCoord=UINT)))
LIGHT = obj(name=STR, type=STR, color=arr(NUM, 3), intensity=NUM, range=NUM,
            spot=obj(innerConeAngle=NUM, outerConeAngle=NUM))

SCHEMA = obj(
    asset=obj(version=STR, minVersion=STR, generator=STR, copyright=STR),
    scene=IDX,
    scenes=arr(obj(name=STR, nodes=arr(IDX))),
    nodes=arr(obj(name=STR, children=arr(IDX), mesh=IDX, skin=IDX, camera=IDX, matrix=arr(NUM, 16),
                  translation=arr(NUM, 3), rotation=arr(NUM, 4), scale=arr(NUM, 3), weights=arr(NUM),
                  extensions=obj(KHR_lights_punctual=obj(light=IDX)))),
    meshes=arr(obj(name=STR, weights=arr(NUM), primitives=arr(obj(
        attributes=("map", IDX), indices=IDX, material=IDX, mode=UINT, targets=arr(("map", IDX)),
        extensions=obj(KHR_draco_mesh_compression=obj(bufferView=IDX, attributes=("map", UINT))))))),
    accessors=arr(obj(bufferView=IDX, byteOffset=UINT, componentType=UINT, normalized=BOOL, count=POS, type=STR,
                      max=arr(NUM), min=arr(NUM), name=STR, sparse=obj(
                          count=POS, indices=obj(bufferView=IDX, byteOffset=UINT, componentType=UINT),
                          values=obj(bufferView=IDX, byteOffset=UINT)))),
    bufferViews=arr(obj(buffer=IDX, byteOffset=UINT, byteLength=POS, byteStride=UINT, target=UINT, name=STR)),
    buffers=arr(obj(uri=STR, byteLength=POS, name=STR)),
    images=arr(obj(uri=STR, mimeType=STR, bufferView=IDX, name=STR)),
    textures=arr(obj(sampler=IDX, source=IDX, name=STR)),
    samplers=arr(obj(magFilter=UINT, minFilter=UINT, wrapS=UINT, wrapT=UINT, name=STR)),
    materials=arr(obj(name=STR, pbrMetallicRoughness=obj(baseColorFactor=arr(NUM, 4), baseColorTexture=TEXINFO,
                                                         metallicFactor=NUM, roughnessFactor=NUM,
                                                         metallicRoughnessTexture=TEXINFO),
                      normalTexture=TEXINFO, occlusionTexture=TEXINFO, emissiveTexture=TEXINFO,
                      emissiveFactor=arr(NUM, 3), alphaMode=STR, alphaCutoff=NUM, doubleSided=BOOL,
                      extensions=obj(KHR_materials_emissive_strength=obj(emissiveStrength=NUM),
                                     KHR_materials_unlit=obj()))),
    skins=arr(obj(inverseBindMatrices=IDX, skeleton=IDX, joints=arr(IDX), name=STR)),
    animations=arr(obj(name=STR, channels=arr(obj(sampler=IDX, target=obj(node=IDX, path=STR))),
                       samplers=arr(obj(input=IDX, output=IDX, interpolation=STR)))),
    cameras=arr(obj(name=STR, type=STR,
                    perspective=obj(aspectRatio=NUM, yfov=NUM, zfar=NUM, znear=NUM),
                    orthographic=obj(xmag=NUM, ymag=NUM, zfar=NUM, znear=NUM))),
    extensionsUsed=arr(STR),
    extensionsRequired=arr(STR),
    extensions=obj(KHR_lights_punctual=obj(lights=arr(LIGHT))),
)

_WANT = {IDX: "an index (integer >= 0)", UINT: "an integer >= 0", POS: "an integer >= 1", INT: "an integer",
         NUM: "a finite number", STR: "a string", BOOL: "true or false"}


def _short(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:50] + "...'"


def _leaf_ok(kind: str, v: Any) -> bool:
    if kind == ANY:
        return True
    if kind == STR:
        return isinstance(v, str)
    if kind == BOOL:
        return isinstance(v, bool)
    if isinstance(v, bool):
        return False
    if kind == NUM:
        return isinstance(v, (int, float)) and math.isfinite(v)
    if not isinstance(v, int):
        return False
    return {IDX: v >= 0, UINT: v >= 0, POS: v >= 1, INT: True}[kind] and abs(v) < 2**53


def check_gltf_types(doc: Any, path: str | os.PathLike[str]) -> None:
    """Raise FormatError (naming ``path`` and the field) on the first field whose JSON type is not
    the one the glTF 2.0 specification gives it."""
    if not isinstance(doc, dict):
        raise FormatError(path, f"expected a JSON object at the top level, got {type(doc).__name__}")
    stack: list[tuple[Schema, Any, str]] = [(SCHEMA, doc, "")]
    while stack:  # iterative: the work is linear in the document's size
        schema, v, field = stack.pop()
        if isinstance(schema, str):
            if not _leaf_ok(schema, v):
                raise FormatError(path, f"expected {_WANT[schema]}, got {_short(v)}", field=field)
            continue
        kind = schema[0]
        if kind == "object":
            if not isinstance(v, dict):
                raise FormatError(path, f"expected an object, got {_short(v)}", field=field or None)
            for k, sub in schema[1].items():
                if k in v:
                    stack.append((sub, v[k], f"{field}.{k}" if field else k))
        elif kind == "map":
            if not isinstance(v, dict):
                raise FormatError(path, f"expected an object, got {_short(v)}", field=field)
            for k, x in v.items():
                stack.append((schema[1], x, f"{field}.{k}"))
        else:  # array
            item, n = schema[1], schema[2]
            if not isinstance(v, list):
                raise FormatError(path, f"expected an array, got {_short(v)}", field=field)
            if n is not None and len(v) != n:
                raise FormatError(path, f"expected {n} elements, got {len(v)}", field=field)
            for i, x in enumerate(v):
                stack.append((item, x, f"{field}[{i}]"))


def _count_values(doc: Any, stop_objects: int, stop_values: int) -> tuple[int, int]:
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


def precheck_gltf(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Check a ``.gltf`` / ``.glb`` before a full parser sees it; returns its JSON document.

    Refuses non-regular files and files over ``safe_io.MAX_MODEL_BYTES``, GLB headers and chunk
    lengths that disagree with the file, JSON nested deeper than ``safe_io.MAX_JSON_DEPTH``,
    top-level arrays longer than ``limits.MAX_GLTF_ITEMS`` (``limits.MAX_GLTF_NODES`` for nodes), and fields of
    the wrong JSON type (:func:`check_gltf_types`).
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
    if len(text) > limits.MAX_GLTF_JSON_BYTES:
        raise FormatError(path, f"JSON of {len(text)} bytes is more than the limit of {limits.MAX_GLTF_JSON_BYTES} (keep "
                                "large buffers in .bin files or a .glb)")
    doc = safe_io.loads_json(text, path)
    if not isinstance(doc, dict):
        raise FormatError(path, f"expected a JSON object at the top level, got {type(doc).__name__}")
    for key in _GLTF_ARRAYS:
        v = doc.get(key)
        if isinstance(v, list):
            limits.check_count(path, key, len(v), limits.MAX_GLTF_NODES if key == "nodes" else limits.MAX_GLTF_ITEMS)
    n_objects, n_values = _count_values(doc, limits.MAX_GLTF_OBJECTS, limits.MAX_GLTF_VALUES)
    if n_objects > limits.MAX_GLTF_OBJECTS or n_values > limits.MAX_GLTF_VALUES:
        raise FormatError(path, f"more than {limits.MAX_GLTF_OBJECTS} JSON objects or {limits.MAX_GLTF_VALUES} values (a glTF "
                                "this large would take minutes to parse)")
    check_gltf_types(doc, path)  # every field piste reads has its specified JSON type
    return doc
