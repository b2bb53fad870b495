"""Pure-Python writers for what the add-on hands piste: the scene ``.toml`` and a height-field ``.npz``.

No ``bpy`` and no numpy here: Blender's own Python runs this module, and so do the tests outside
Blender.  The add-on gathers a plain ``dict`` shaped like piste's scene file
(``piste.world.scene_file``: ``name``, ``terrain``, ``lightmap``, ``lod``, ``visibility``,
``render``, ``gltf`` [...], ``riders`` [...], ``objects`` [...], ``lights`` [...], ``cameras`` [...])
and :func:`dumps_scene` writes it as TOML that piste's loader reads back to the same values.

Every writer writes only when the bytes change (:func:`write_if_changed`), so that the live
preview (``piste view`` polling the files' stamps) rebuilds only when something really changed.

API
---
dumps_scene(scene: dict) -> str                  TOML text (tables, arrays of tables, inline tables)
npy_bytes(values, shape) -> bytes               a little-endian float64 ``.npy`` (format 1.0)
heightfield_npz_bytes(z_rows, dx, dy) -> bytes   ``.npz`` with ``z`` (rows x cols float64), ``dx``, ``dy``
write_if_changed(path, data: bytes) -> bool     atomic (temporary file + rename); True when written
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import struct
import zipfile
from array import array
from pathlib import Path

__all__ = ["dumps_scene", "npy_bytes", "heightfield_npz_bytes", "write_if_changed", "SceneWriteError",
           "TABLE_ORDER", "ARRAY_ORDER"]

#: the scene file's tables and arrays of tables, in the order piste's documentation gives them
TABLE_ORDER = ("terrain", "lightmap", "lod", "visibility", "render")
ARRAY_ORDER = ("gltf", "riders", "objects", "lights", "cameras")
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


class SceneWriteError(ValueError):
    """A value the add-on cannot write as TOML (names the key and what was expected)."""


def _key(k: str) -> str:
    if not isinstance(k, str) or not k:
        raise SceneWriteError(f"expected a non-empty string key, got {k!r}")
    return k if _BARE_KEY.match(k) else json.dumps(k)


def _value(v, where: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            raise SceneWriteError(f"{where}: expected a number, got NaN")
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        r = repr(v)
        return r if ("." in r or "e" in r or "n" in r) else r + ".0"
    if isinstance(v, str):
        # JSON's escapes are TOML basic-string escapes (\" \\ \n \t \uXXXX); no raw control characters
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x, f"{where}[{i}]") for i, x in enumerate(v)) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x, f'{where}.{k}')}" for k, x in v.items()) + " }"
    raise SceneWriteError(f"{where}: cannot write {type(v).__name__} {v!r} as TOML")


def _body(table: dict, where: str) -> list:
    return [f"{_key(k)} = {_value(v, f'{where}.{k}')}" for k, v in table.items() if v is not None]


def dumps_scene(scene: dict, header: str = "") -> str:
    """The scene ``dict`` as TOML: top-level values first, then the tables of :data:`TABLE_ORDER`
    and the arrays of tables of :data:`ARRAY_ORDER` (anything else after them, in the dict's order).
    ``None`` values are left out (piste's default applies)."""
    lines = [f"# {ln}".rstrip() for ln in header.splitlines()]
    tables = [k for k in TABLE_ORDER if k in scene] + [k for k, v in scene.items()
                                                       if isinstance(v, dict) and k not in TABLE_ORDER]
    arrays = [k for k in ARRAY_ORDER if k in scene] + [k for k, v in scene.items()
                                                       if isinstance(v, list) and v and isinstance(v[0], dict)
                                                       and k not in ARRAY_ORDER]
    top = {k: v for k, v in scene.items() if k not in tables and k not in arrays}
    lines += _body(top, "")
    for k in tables:
        if scene[k]:
            lines += ["", f"[{_key(k)}]"] + _body(scene[k], k)
    for k in arrays:
        for i, item in enumerate(scene[k] or ()):
            lines += ["", f"[[{_key(k)}]]"] + _body(item, f"{k}[{i}]")
    return "\n".join(lines).lstrip("\n") + "\n"


def npy_bytes(values, shape) -> bytes:
    """``values`` (a flat sequence of numbers, row-major) as a ``.npy`` of ``shape``, ``<f8``."""
    shape = tuple(int(s) for s in shape)
    n = 1
    for s in shape:
        n *= s
    data = array("d", (float(x) for x in values))
    if len(data) != n:
        raise SceneWriteError(f"expected {n} values for shape {shape}, got {len(data)}")
    if struct.pack("=H", 1) != struct.pack("<H", 1):
        data.byteswap()
    shape_text = "(" + "".join(f"{s}, " for s in shape).rstrip(" ") + ")" if len(shape) != 1 else f"({shape[0]},)"
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': %s, }" % shape_text
    pad = 64 - (10 + len(header) + 1) % 64
    header = header + " " * (pad % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1") + data.tobytes()


def heightfield_npz_bytes(z_rows, dx: float, dy: float) -> bytes:
    """A height-field ``.npz`` piste reads (``terrain.source``): ``z`` (rows x cols metres, row ``i``
    at ``y = i dy``, column ``j`` at ``x = j dx``), ``dx`` and ``dy`` (metres between samples)."""
    rows = [list(r) for r in z_rows]
    if not rows or any(len(r) != len(rows[0]) for r in rows):
        raise SceneWriteError("height field: expected equal rows of samples")
    if not (dx > 0 and dy > 0):
        raise SceneWriteError(f"height field: expected spacing > 0, got dx={dx}, dy={dy}")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for name, data in (("z", npy_bytes([x for r in rows for x in r], (len(rows), len(rows[0])))),
                           ("dx", npy_bytes([dx], (1,))), ("dy", npy_bytes([dy], (1,)))):
            info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))  # same bytes for the same field
            zf.writestr(info, data)
    return buf.getvalue()


def write_if_changed(path, data: bytes) -> bool:
    """Write ``data`` to ``path`` atomically unless it already holds exactly these bytes."""
    path = Path(path)
    try:
        if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
            return False
    except OSError:
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return True
