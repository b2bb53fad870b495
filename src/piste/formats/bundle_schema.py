"""The types of a ``.piste`` bundle manifest, checked when the bundle is read.

The SHA-256 sums in a bundle's manifest cover its arrays, not the manifest itself: a damaged or
hand-edited manifest reached the loaders as ``KeyError 'origin'``, ``int('eight')`` or a
``RecursionError``.  :func:`check_manifest` checks every field the loaders read (types, sizes,
the ``members`` table) and raises :class:`~piste.errors.FormatError` naming the bundle and the
field (``manifest.json: visibility.shape: expected 2 integers >= 1, got "eight"``).  Fields it
does not know are left alone (reports, statistics).

API
---
check_manifest(man, path)       FormatError on the first field of the wrong type or size
MAX_MEMBER_BYTES, MAX_BUNDLE_BYTES
"""

from __future__ import annotations

import math
import os
from typing import Any

from piste.errors import FormatError

__all__ = ["check_manifest", "MAX_MEMBER_BYTES", "MAX_BUNDLE_BYTES"]

#: largest array member (uncompressed), and all members together
MAX_MEMBER_BYTES = 4 << 30
MAX_BUNDLE_BYTES = 16 << 30
#: largest count a manifest may give (frames, bones, cells, ...)
MAX_COUNT = 1 << 31

NUM, POSNUM, UINT, POS, STR, BOOL, ANY = "number", "number > 0", "integer >= 0", "integer >= 1", "string", "bool", "any"
NUM_OR_NULL, STR_OR_NULL = "number or null", "string or null"


#: a schema: a kind name (NUM, STR, ...) or a nested ("array" | "object" | "map", ...) tuple
Schema = Any


def arr(item: Schema, n: int | None = None) -> tuple[str, Schema, int | None]:
    return ("array", item, n)


def obj(**fields: Schema) -> tuple[str, dict[str, Schema]]:
    return ("object", fields)


def mapping(item: Schema) -> tuple[str, Schema]:
    return ("map", item)


LIGHT = obj(name=STR, color=arr(NUM, 3), intensity=NUM, direction=arr(NUM, 3), position=arr(NUM, 3),
            shadows=BOOL, falloff=NUM, inner_angle=NUM, outer_angle=NUM)
SCHEMA = obj(
    name=STR,
    members=mapping(obj(shape=arr(UINT), dtype=STR, sha256=STR)),
    terrain=obj(name=STR, tol=NUM_OR_NULL, patches=UINT, topology=POS),
    lightmap=obj(res=POS, gutter=UINT),
    lights=obj(ambient=arr(LIGHT), directional=arr(LIGHT), point=arr(LIGHT), spot=arr(LIGHT)),
    cameras=arr(obj(name=STR, eye=arr(NUM, 3), target=arr(NUM, 3), up=arr(NUM, 3), fov_y=POSNUM, near=POSNUM,
                    far=POSNUM, ortho_height=NUM_OR_NULL, track=ANY)),
    visibility=obj(cell=POSNUM, shape=arr(POS, 2), origin=arr(NUM, 2), eye_heights=arr(NUM), method=STR,
                   n_patches=UINT, n_objects=UINT),
    objects=obj(kinds=arr(STR), instances=arr(STR), meshes=mapping(obj(normal_bits=POS, radius=NUM))),
    riders=arr(obj(name=STR, character=STR, clip=STR, heading=NUM, phase=NUM, scale=NUM)),
    characters=mapping(obj(name=STR, bones=arr(STR), morphs=arr(STR), rate=POSNUM, max_bones=POS,
                           clips=mapping(obj(duration=NUM, frames=POS)),
                           lods=arr(obj(name=STR, ratio=NUM, step=NUM, palette=UINT, batches=UINT))),
               ),
    render=obj(size=arr(POS, 2), lightmap_mode=STR, object_lod=NUM),
)


def _short(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:50] + "...'"


def _ok(kind: str, v: Any) -> bool:
    if kind == ANY:
        return True
    if kind == STR:
        return isinstance(v, str)
    if kind == STR_OR_NULL:
        return v is None or isinstance(v, str)
    if kind == BOOL:
        return isinstance(v, bool)
    if v is None:
        return kind == NUM_OR_NULL
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    if kind in (NUM, NUM_OR_NULL):
        return math.isfinite(v)
    if kind == POSNUM:
        return math.isfinite(v) and v > 0
    return isinstance(v, int) and (v >= 0 if kind == UINT else v >= 1) and v <= MAX_COUNT


def check_manifest(man: Any, path: str | os.PathLike[str]) -> None:
    """Raise FormatError (naming ``path`` and the manifest field) on the first field of the wrong
    type or an absurd size; also bounds each member's and the total declared array bytes."""
    stack: list[tuple[Schema, Any, str]] = [(SCHEMA, man, "")]
    while stack:  # iterative and linear in the manifest's size
        schema, v, fld = stack.pop()
        where = f"manifest.json: {fld}" if fld else "manifest.json"
        if isinstance(schema, str):
            if not _ok(schema, v):
                raise FormatError(path, f"{where}: expected {'a' if schema[0] not in 'ai' else 'an'} {schema}, "
                                        f"got {_short(v)}", field=fld or None)
            continue
        if v is None and fld.count(".") == 0 and fld != "members":
            continue  # an optional section left out (``"visibility": null`` when it is disabled)
        if schema[0] in ("object", "map"):
            if not isinstance(v, dict):
                raise FormatError(path, f"{where}: expected an object, got {_short(v)}", field=fld or None)
            items = schema[1].items() if schema[0] == "object" else ((k, schema[1]) for k in v)
            for k, sub in items:
                if k in v:
                    stack.append((sub, v[k], f"{fld}.{k}" if fld else str(k)))
        else:
            item, n = schema[1], schema[2]
            if not isinstance(v, list) or (n is not None and len(v) != n):
                want = f"{n} elements" if n is not None else "an array"
                raise FormatError(path, f"{where}: expected {want}, got {_short(v)}", field=fld)
            for i, x in enumerate(v):
                stack.append((item, x, f"{fld}[{i}]"))
    total = 0
    for name, info in man.get("members", {}).items():
        n = math.prod(info.get("shape", [])) if info.get("shape") is not None else 0
        if n * 16 > MAX_MEMBER_BYTES:
            raise FormatError(path, f"manifest.json: members.{name}: shape {info['shape']} is larger than the limit of "
                                    f"{MAX_MEMBER_BYTES} bytes", field=f"members.{name}")
        total += n
    if total * 16 > MAX_BUNDLE_BYTES:
        raise FormatError(path, f"manifest.json: the members hold more than {MAX_BUNDLE_BYTES} bytes", field="members")
