"""Reading files that other files name, safely: confinement, special files, size caps.

A model, scene or bundle is untrusted input.  When it names another file (a glTF ``buffers[].uri``
or ``images[].uri``, a height field) that file is read only if

- the reference is a relative path that stays inside the referring file's folder after ``..`` and
  symbolic links are resolved, or lies inside one of the folders the caller explicitly allowed
  (``allow_paths``: the ``load_gltf(..., allow_paths=[...])`` keyword and the scene file's top-level
  ``allow_paths = [...]`` key).  Absolute paths and URLs (``file:``, ``http:``) are refused unless
  they fall inside an allowed folder (URLs never);
- it is a regular file (``os.stat`` / ``S_ISREG`` before opening: devices such as ``/dev/zero``,
  named pipes, sockets and folders are refused, and the file is opened ``O_NONBLOCK | O_NOFOLLOW``
  so nothing can hang or swap in a link between the check and the read);
- its size, and any length the referring file declares for it, is within a cap checked *before*
  a byte is read or a buffer allocated.

Data URIs are size-checked from their text before decoding.  Errors are
:class:`~piste.errors.FormatError` naming the referring file and field.

API
---
resolve_reference(owner, ref, allow_paths=(), field=None) -> Path   confined, symlink-free path
read_regular(path, max_bytes, owner=None, field=None, length=None) -> bytes
check_regular(path, max_bytes, owner=None, field=None) -> int       size in bytes
decode_data_uri(uri, max_bytes, owner=None, field=None) -> bytes
loads_json(data, path, max_depth=MAX_JSON_DEPTH) -> object         json.loads with bounded nesting
json_depth(obj) -> int                                              nesting depth (iterative)
text_depth(text) -> int                                             nesting depth of JSON text, unparsed
toml_depth(text) -> int                                             nesting depth of TOML text, unparsed
Limits: MAX_MODEL_BYTES, MAX_BUFFER_BYTES, MAX_IMAGE_BYTES, MAX_IMAGE_PIXELS, MAX_JSON_DEPTH
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import re
import stat
import urllib.parse
from pathlib import Path

import numpy as np

from piste.errors import FormatError

__all__ = [
    "resolve_reference",
    "read_regular",
    "check_regular",
    "decode_data_uri",
    "loads_json",
    "json_depth",
    "MAX_MODEL_BYTES",
    "MAX_BUFFER_BYTES",
    "MAX_IMAGE_BYTES",
    "MAX_IMAGE_PIXELS",
    "MAX_JSON_DEPTH",
    "MAX_TOML_BYTES",
]

#: largest model file (``.gltf`` / ``.glb``) read at all
MAX_MODEL_BYTES = 1 << 30
#: largest single glTF buffer (external file or data URI), bytes
MAX_BUFFER_BYTES = 1 << 30
#: largest encoded image file, bytes
MAX_IMAGE_BYTES = 256 << 20
#: largest decoded image (texture or height field), pixels: 16384 x 16384 would be 1 GiB of RGBA
MAX_IMAGE_PIXELS = 64 << 20
#: deepest JSON nesting accepted (glTF, bundle manifests); real files nest < 10 deep
MAX_JSON_DEPTH = 64
#: largest scene or light TOML text: hand-written files are a few KB (tomllib takes ~1 s per 10 MB)
MAX_TOML_BYTES = 16 << 20

_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
_DRIVE = re.compile(r"^[A-Za-z]:[\\/]")


def _err(owner, field, message) -> FormatError:
    return FormatError(owner, message, field=field)


def _within(target: str, root: str) -> bool:
    return target == root or target.startswith(root.rstrip(os.sep) + os.sep)


def resolve_reference(owner, ref: str, allow_paths=(), field: str | None = None) -> Path:
    """The file that relative reference ``ref`` (a URI, percent-encoded) inside file ``owner`` names.

    Returns the real path (no ``..``, no symbolic links).  Raises FormatError (naming ``owner`` and
    ``field``) when ``ref`` is a URL, an absolute path, or resolves outside ``owner``'s folder and
    every folder of ``allow_paths``.
    """
    owner = Path(owner)
    if not isinstance(ref, str) or not ref:
        raise _err(owner, field, f"expected a relative file path, got {ref!r}")
    text = urllib.parse.unquote(ref)
    if "\x00" in text:
        raise _err(owner, field, "file path contains a NUL character")
    allowed = [os.path.realpath(a) for a in allow_paths]
    if _SCHEME.match(text) and not _DRIVE.match(text):
        raise _err(owner, field, f"{_short(ref)} is a URL: only relative file paths inside the model's folder "
                                 "(or data: URIs) are read")
    absolute = os.path.isabs(text) or text.startswith("\\") or bool(_DRIVE.match(text))
    base = os.path.realpath(owner.parent)
    target = os.path.realpath(os.path.join(base, text))
    if absolute:
        if not any(_within(target, a) for a in allowed):
            raise _err(owner, field, f"{_short(ref)} is an absolute path: only paths relative to the model's folder "
                                     "are read (allow other folders with allow_paths)")
        return Path(target)
    if not any(_within(target, r) for r in [base] + allowed):
        raise _err(owner, field, f"{_short(ref)} leaves the model's folder {base} (it resolves to {target}); "
                                 "allow other folders explicitly with allow_paths")
    return Path(target)


def _short(ref) -> str:
    s = repr(ref)
    return s if len(s) <= 120 else s[:100] + "...'"


def check_regular(path, max_bytes: int, owner=None, field: str | None = None, what: str = "file") -> int:
    """Size of ``path`` after checking it is a regular file of at most ``max_bytes`` (stat only,
    nothing is opened)."""
    owner = path if owner is None else owner
    try:
        st = os.stat(path)
    except OSError as e:
        raise _err(owner, field, f"cannot read {what} {str(path)!r}: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode):
        raise _err(owner, field, f"{what} {str(path)!r} is not a regular file (a folder, device, pipe or socket)")
    if st.st_size > max_bytes:
        raise _err(owner, field, f"{what} {str(path)!r} has {st.st_size} bytes, more than the limit of {max_bytes}")
    return st.st_size


def read_regular(path, max_bytes: int, owner=None, field: str | None = None, length: int | None = None,
                 what: str = "file", length_field: str | None = None) -> bytes:
    """The bytes of regular file ``path`` (all of them, or the first ``length``).

    Refuses (FormatError naming ``owner``/``field``) devices, pipes, sockets and folders before
    opening, files over ``max_bytes`` and files shorter than ``length``.  Opens with
    ``O_NOFOLLOW | O_NONBLOCK`` and checks the opened file again (``fstat``), so a swap between the
    check and the open cannot make it read a device or hang on a pipe.
    """
    owner = path if owner is None else owner
    lfield = length_field or field
    if length is not None:
        if isinstance(length, bool) or not isinstance(length, int) or length < 0:
            raise _err(owner, lfield, f"expected a byte length >= 0, got {length!r}")
        if length > max_bytes:
            raise _err(owner, lfield, f"declares {length} bytes, more than the limit of {max_bytes}")
    size = check_regular(path, max_bytes if length is None else 1 << 62, owner, field, what)
    want = size if length is None else length
    if size < want:
        raise _err(owner, lfield, f"declares {length} bytes but {what} {str(path)!r} has only {size}")
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as e:
        raise _err(owner, field, f"cannot read {what} {str(path)!r}: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size < want:
            raise _err(owner, field, f"{what} {str(path)!r} changed while being opened")
        chunks, got = [], 0
        while got < want:  # bounded: at most `want` bytes, stops at end of file
            b = os.read(fd, min(want - got, 16 << 20))
            if not b:
                break
            chunks.append(b)
            got += len(b)
    except OSError as e:
        raise _err(owner, field, f"cannot read {what} {str(path)!r}: {e.strerror or e}") from None
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) < want:
        raise _err(owner, field, f"{what} {str(path)!r} ended after {len(data)} of {want} bytes")
    return data


def decode_data_uri(uri: str, max_bytes: int, owner=None, field: str | None = None) -> bytes:
    """The bytes of a ``data:`` URI, refusing (before decoding) any that would exceed ``max_bytes``."""
    head, sep, data = uri.partition(",")
    if not sep:
        raise _err(owner, field, "bad data URI: no ',' before the data")
    b64 = head.endswith(";base64")
    estimate = len(data) * 3 // 4 if b64 else len(data)
    if estimate > max_bytes + 2:  # base64 padding ('=') makes the estimate up to 2 bytes high
        raise _err(owner, field, f"data URI holds about {estimate} bytes, more than the limit of {max_bytes}")
    try:
        out = base64.b64decode(data) if b64 else urllib.parse.unquote_to_bytes(data)
    except (binascii.Error, ValueError) as e:
        raise _err(owner, field, f"bad data URI: {e}") from None
    if len(out) > max_bytes:
        raise _err(owner, field, f"data URI holds {len(out)} bytes, more than the limit of {max_bytes}")
    return out


def json_depth(obj) -> int:
    """Nesting depth of a parsed JSON value (a scalar is 0, ``[]`` is 1), computed without recursion."""
    depth, stack = 0, [(obj, 0)]
    while stack:
        o, d = stack.pop()
        if isinstance(o, dict):
            o = list(o.values())
        if isinstance(o, list):
            depth = max(depth, d + 1)
            stack.extend((x, d + 1) for x in o if isinstance(x, (dict, list)))
    return depth


# "unrolled" string patterns: a run of plain characters is one regex step (no backtracking state
# per character: the naive (?:[^"\\]|\\.)* needed gigabytes on a 40 MB data URI)
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.S)


def text_depth(data) -> int:
    """Deepest ``[`` / ``{`` nesting of JSON text, found without parsing (strings skipped), so a
    deep document is refused before a recursive parser sees it."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else bytes(data)
    b = np.frombuffer(_STRING.sub(b'""', raw), dtype=np.uint8)
    opens = (b == ord("[")) | (b == ord("{"))
    br = opens[opens | (b == ord("]")) | (b == ord("}"))]  # the brackets only, in order
    return int(np.cumsum(np.where(br, 1, -1)).max(initial=0))


_TOML_STRING = re.compile(r'"""[^\\"]*(?:(?:\\.|"(?!""))[^\\"]*)*"""|\'\'\'.*?\'\'\'|"[^"\\\n]*(?:\\.[^"\\\n]*)*"'
                          r'|\'[^\'\n]*\'|#[^\n]*', re.S)


def toml_depth(text: str) -> int:
    """Deepest ``[`` / ``{`` nesting of TOML text (strings and comments skipped), measured before
    parsing: :mod:`tomllib` recurses on nested arrays and would raise RecursionError."""
    return text_depth(_TOML_STRING.sub('""', text).replace('"', " "))


def loads_json(data, path, max_depth: int = MAX_JSON_DEPTH, field: str | None = None):
    """``json.loads(data)`` whose errors (syntax, encoding, nesting deeper than ``max_depth``) are
    FormatErrors naming ``path``; the nesting is measured on the text before parsing."""
    if text_depth(data) > max_depth:
        raise _err(path, field, f"JSON nested too deeply (more than {max_depth} levels)")
    try:
        doc = json.loads(data)
    except RecursionError:
        raise _err(path, field, f"JSON nested too deeply (more than {max_depth} levels)") from None
    except json.JSONDecodeError as e:
        raise FormatError(path, f"not valid JSON: {e.msg} (column {e.colno})", line=e.lineno, field=field) from None
    except (ValueError, TypeError) as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise _err(path, field, f"not valid JSON ({e})") from None
    if json_depth(doc) > max_depth:
        raise _err(path, field, f"JSON nested too deeply (more than {max_depth} levels)")
    return doc
