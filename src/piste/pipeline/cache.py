"""A content-hash keyed cache of build steps.

Each step's output is a set of named arrays plus a JSON-able ``meta`` dict, stored in
``<root>/<step>/<key>.npz`` where ``key`` is a SHA-256 over everything the step reads (file bytes,
settings, the keys of the steps it depends on, the step's version).  Changing an input changes
the key, so a rebuild recomputes exactly the steps downstream of the change and reuses the rest.
Entries are written atomically with fixed zip timestamps (equal content, equal bytes); a corrupt
entry is treated as missing.

API
---
::

    Hasher                          incremental SHA-256 over bytes, str, JSON, arrays and files
    content_key(*parts) -> str      hex key of the parts
    Cache(root)                     ``get(step, key)``, ``put(step, key, arrays, meta)``, ``path(step, key)``
    npz_bytes(arrays) -> bytes      deterministic .npz bytes
    cache_root() -> Path            piste's own cache folder (built default scenes, baked light maps)
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from piste.extras import environ
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import read_regular

__all__ = ["Hasher", "content_key", "Cache", "npz_bytes", "read_npz_bytes", "cache_root"]

_EPOCH = (1980, 1, 1, 0, 0, 0)


def cache_root() -> Path:
    """piste's cache folder, the one place it is decided: ``$PISTE_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/piste`` (the XDG base directories), else ``~/.cache/piste``.  Built default
    scenes live in ``scenes/``, baked light maps in ``lightmaps/``.  (A scene's own step cache is
    beside the scene: :func:`piste.pipeline.build.default_cache_dir`.)"""
    own = environ("PISTE_CACHE_DIR")
    if own:
        return Path(own).expanduser()
    xdg = environ("XDG_CACHE_HOME")
    if xdg and Path(xdg).is_absolute():  # the spec: a relative path is invalid and ignored
        return Path(xdg) / "piste"
    return Path.home() / ".cache" / "piste"


class Hasher:
    """SHA-256 over a sequence of typed parts (each part is tagged, so ``("ab",)`` != ``("a", "b")``)."""

    def __init__(self, *parts: Any) -> None:
        self._h = hashlib.sha256()
        for p in parts:
            self.update(p)

    def update(self, part: Any) -> "Hasher":
        h = self._h
        if isinstance(part, Path):  # a source file: opened like its reader opens it (piste.formats.safe_io)
            data = read_regular(part, 1 << 40, what="source file")
            h.update(b"F%d:" % len(data))
            h.update(data)
        elif isinstance(part, (bytes, bytearray, memoryview)):
            h.update(b"B%d:" % len(part))
            h.update(part)
        elif isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            head = f"A{a.dtype.str}{a.shape}:".encode()
            h.update(head)
            h.update(a.tobytes())
        elif isinstance(part, str):
            b = part.encode()
            h.update(b"S%d:" % len(b))
            h.update(b)
        else:
            b = json.dumps(part, sort_keys=True, default=_json_default).encode()
            h.update(b"J%d:" % len(b))
            h.update(b)
        return self

    def hexdigest(self) -> str:
        return self._h.hexdigest()


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (Path, tuple)):
        return str(x) if isinstance(x, Path) else list(x)
    raise TypeError(f"cannot hash {type(x).__name__}")


def content_key(*parts: Any) -> str:
    """Hex SHA-256 of ``parts`` (see :class:`Hasher`)."""
    return Hasher(*parts).hexdigest()


def npz_bytes(arrays: dict, compress: bool = False) -> bytes:
    """A .npz (zip of .npy) with sorted members and fixed timestamps: equal arrays, equal bytes."""
    buf = io.BytesIO()
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(buf, "w", compression=method) as zf:
        for name in sorted(arrays):
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
            info.compress_type = method
            info.external_attr = 0o644 << 16
            data = io.BytesIO()
            np.lib.format.write_array(data, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            zf.writestr(info, data.getvalue())
    return buf.getvalue()


def read_npz_bytes(data: bytes) -> dict:
    """Arrays of :func:`npz_bytes` output: ``{name: array}``."""
    out = {}
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        for name in zf.namelist():
            out[name[:-4] if name.endswith(".npy") else name] = np.lib.format.read_array(
                io.BytesIO(zf.read(name)), allow_pickle=False)
    return out


class Cache:
    """Build-step cache in folder ``root`` (``None``: a cache that stores nothing)."""

    def __init__(self, root: str | Path | None) -> None:
        self.root = Path(root) if root is not None else None
        self.hits: list = []
        self.misses: list = []

    def path(self, step: str, key: str) -> Path | None:
        return None if self.root is None else self.root / step / f"{key}.npz"

    def get(self, step: str, key: str) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
        """``(arrays dict, meta dict)`` of a stored entry, or None."""
        p = self.path(step, key)
        if p is None or not p.exists():
            self.misses.append(step)
            return None
        try:
            arrays = read_npz_bytes(p.read_bytes())
            meta = json.loads(bytes(arrays.pop("__meta__")).decode())
        except Exception:  # a corrupt or partial entry: recompute
            self.misses.append(step)
            return None
        self.hits.append(step)
        return arrays, meta

    def put(self, step: str, key: str, arrays: dict, meta: dict | None = None) -> None:
        p = self.path(step, key)
        if p is None:
            return
        data = dict(arrays)
        data["__meta__"] = np.frombuffer(json.dumps(meta or {}, sort_keys=True, default=_json_default).encode(), np.uint8)
        write_bytes_atomic(p, npz_bytes(data))
