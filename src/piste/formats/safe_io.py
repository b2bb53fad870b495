"""Reading files that other files name, safely: one confinement rule, race-free opens, size caps.

A model, scene, tiled world or Multitool project is untrusted input (a mod downloaded from a
stranger).  Every reader in piste opens files through this module, and the rule is the same for
every kind of reference (scene paths, glTF URIs, tiles, Multitool textures, SSX partner files):

- **Confinement**: a reference resolves inside the folder of the file that names it, or inside a
  folder the *user* allowed: ``--allow-path DIR`` on the command line (:func:`set_user_allow_paths`),
  the ``PISTE_ALLOW_PATHS`` environment variable, or the ``allow_paths=`` keyword of a library call.
  A key inside the file being read never widens it (a scene's ``allow_paths`` key is an error).
  ``..`` out of the folder, absolute paths elsewhere and URLs are refused by name.
- **No links, no races**: the folder of a file the user named (a scene, a model, a tiled world, a
  Multitool project) is a *confinement root* (:func:`add_root`, :func:`anchor`); every open below a
  root walks from it one component at a time with ``openat(dir_fd, part, O_NOFOLLOW |
  O_DIRECTORY)`` (:func:`open_regular`), so a symbolic link anywhere below the root, file or
  folder, present or swapped in while the loader runs, is refused.  A path the user typed is taken
  through its folder's real path, and its last component is not followed either (a file found
  beside it by name, an SSX level's ``.ssh``, cannot be a link out; name a link's target).
  The last component is opened ``O_PATH`` and ``fstat``-ed: folders, devices (``/dev/zero``), named
  pipes and sockets are refused before any read (a pipe never blocks, a device is never opened);
  only then is the same inode reopened for reading.  (``openat2(RESOLVE_BENEATH |
  RESOLVE_NO_SYMLINKS)`` would do the walk in one call; the walk works on every POSIX kernel.)
- **Sizes**: a file's size, and any length the referring file declares for it, is within a cap
  checked *before* a byte is read or a buffer allocated.

Data URIs are size-checked from their text before decoding.  Errors are
:class:`~piste.errors.FormatError` naming the referring file and field.

API
---
resolve_reference(owner, ref, allow_paths=(), field=None) -> Path   confined absolute path (not opened)
open_regular(path, max_bytes, owner=None, field=None) -> int        race-free descriptor of a regular file
open_file(path, max_bytes, ...) -> BinaryIO                          the same as a file object
read_regular(path, max_bytes, owner=None, field=None, length=None) -> bytes
read_reference(owner, ref, max_bytes, allow_paths=(), field=None) -> bytes
check_regular(path, max_bytes, owner=None, field=None) -> int       size in bytes (opened O_PATH, fstat)
confined_file(owner, ref, ...) -> Path / confined_folder(owner, ref, ...) -> Path
set_user_allow_paths(dirs) / user_allow_paths() -> tuple[Path]      --allow-path, PISTE_ALLOW_PATHS
add_root(folder) -> str / anchor(folder) -> str                     confinement roots
decode_data_uri(uri, max_bytes, owner=None, field=None) -> bytes
loads_json(data, path, max_depth=MAX_JSON_DEPTH) -> object         json.loads with bounded nesting
json_depth(obj) -> int                                              nesting depth (iterative)
text_depth(text) -> int                                             nesting depth of JSON text, unparsed
toml_depth(text) -> int                                             nesting depth of TOML text, unparsed
loads_toml(text, path, what, error) -> dict                         tomllib.loads with the size/depth/syntax guards
Limits: MAX_MODEL_BYTES, MAX_BUFFER_BYTES, MAX_IMAGE_BYTES, MAX_IMAGE_PIXELS, MAX_JSON_DEPTH
"""

from __future__ import annotations

import base64
import binascii
import errno
import io
import json
import os
import re
import stat
import threading
import urllib.parse
from collections.abc import Iterable
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np

from piste.errors import ConfigError, FormatError
from piste.extras import environ

__all__ = [
    "resolve_reference",
    "read_regular",
    "read_reference",
    "open_regular",
    "open_file",
    "confined_file",
    "confined_folder",
    "add_root",
    "anchor",
    "set_user_allow_paths",
    "user_allow_paths",
    "ALLOW_PATHS_ENV",
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
#: deepest array / table nesting a TOML file piste reads may have (real ones nest 2 or 3 deep)
MAX_TOML_DEPTH = 32

_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
_DRIVE = re.compile(r"^[A-Za-z]:[\\/]")


def _err(owner: str | os.PathLike[str] | None, field: str | None, message: str) -> FormatError:
    e = FormatError(owner, message, field=field)
    e.reason = message  # the message without the file and field (callers that name them their own way)
    return e


def _within(target: str, root: str) -> bool:
    return target == root or target.startswith(root.rstrip(os.sep) + os.sep)


# ----------------------------------------------------------------------------- folders the user allows
#: environment variable naming extra folders (``os.pathsep``-separated) references may read
ALLOW_PATHS_ENV = "PISTE_ALLOW_PATHS"
_user_allowed: list[str] = []  # real paths set by the command line (--allow-path DIR)
_lock = threading.Lock()


def _folder_list(paths: Iterable[str | os.PathLike[str]], source: str) -> list[str]:
    out = []
    for p in paths:
        text = os.fspath(p)
        if not text or "\x00" in text:
            raise ConfigError(f"{source}: expected a folder, got {text!r}")
        real = os.path.realpath(os.path.expanduser(text))
        if not os.path.isdir(real):
            raise ConfigError(f"{source} {text!r}: not a folder (looked for {real})")
        out.append(real)
    return out


def set_user_allow_paths(paths: Iterable[str | os.PathLike[str]] | None, source: str = "--allow-path") -> tuple[Path, ...]:
    """The folders the *user* named on the command line (``--allow-path DIR``, repeatable) that every
    reference may read besides the referring file's own folder.  Replaces the previous set; returns
    :func:`user_allow_paths`.  ConfigError (naming ``source``) for a path that is not a folder."""
    folders = _folder_list(paths or (), source)
    with _lock:
        _user_allowed[:] = folders
    for f in folders:
        add_root(f)
    return tuple(Path(f) for f in folders)


def user_allow_paths() -> tuple[Path, ...]:
    """Real paths of the folders the user allows: ``--allow-path`` (:func:`set_user_allow_paths`)
    and the ``PISTE_ALLOW_PATHS`` environment variable.  A key inside a file never adds to them."""
    out = list(_user_allowed) + list(_env_folders(environ(ALLOW_PATHS_ENV) or ""))
    return tuple(Path(p) for p in dict.fromkeys(out))


_env_cache: dict = {}


def _env_folders(value: str) -> tuple:
    """The real folders of a PISTE_ALLOW_PATHS value (checked and registered once per value)."""
    if value not in _env_cache:
        folders = tuple(_folder_list([p for p in value.split(os.pathsep) if p], ALLOW_PATHS_ENV))
        for f in folders:
            add_root(f)
        _env_cache.clear()
        _env_cache[value] = folders
    return _env_cache[value]


# ----------------------------------------------------------------------------- confinement roots
_roots: set = set()  # real folders below which every component is opened with O_NOFOLLOW


def add_root(folder: str | os.PathLike[str]) -> str:
    """Register ``folder`` (a folder the user named, or the folder of a file the user named) as a
    confinement root: every later open of a path below it walks from it one component at a time
    with ``O_NOFOLLOW`` (:func:`open_regular`).  Returns its real path."""
    a = os.path.abspath(os.fspath(folder))
    under = _root_of(a)
    real = os.path.normpath(a) if under is not None else os.path.realpath(a)
    if under is None:
        with _lock:
            _roots.add(real)
    return real


def _root_of(abspath: str) -> str | None:
    """The shortest registered root holding ``abspath`` (the strictest walk), or None."""
    with _lock:
        if not _roots:
            return None
        best, p = None, abspath
        while True:
            if p in _roots:
                best = p
            parent = os.path.dirname(p)
            if parent == p:
                return best
            p = parent


def anchor(folder: str | os.PathLike[str]) -> str:
    """The folder references inside a file of ``folder`` resolve against: an absolute, normalised
    path without links.  Below a registered root it is taken lexically (the open walks it and
    refuses any link swapped in); otherwise it is the user's own folder, resolved and registered."""
    a = os.path.normpath(os.path.abspath(os.fspath(folder)))
    return a if _root_of(a) is not None else add_root(a)


def resolve_reference(owner: str | os.PathLike[str], ref: str, allow_paths: Iterable[str | os.PathLike[str]] = (), field: str | None = None, what: str = "model") -> Path:
    """The file that relative reference ``ref`` (a URI, percent-encoded) inside file ``owner`` names.

    Returns an absolute, normalised path inside ``owner``'s folder or a folder the user allowed
    (``allow_paths``, ``--allow-path``, ``PISTE_ALLOW_PATHS``).  Raises FormatError (naming
    ``owner`` and ``field``) when ``ref`` is a URL, an absolute path elsewhere, or leaves those
    folders.  Nothing is opened: :func:`open_regular` walks the path and refuses links.
    """
    owner = Path(owner)
    if not isinstance(ref, str) or not ref:
        raise _err(owner, field, f"expected a relative file path, got {ref!r}")
    text = urllib.parse.unquote(ref) if what == "model" else ref
    if "\x00" in text:
        raise _err(owner, field, "file path contains a NUL character")
    allowed = [os.path.realpath(a) for a in allow_paths] + [str(p) for p in user_allow_paths()]
    for a in allowed:
        add_root(a)
    if _SCHEME.match(text) and not _DRIVE.match(text):
        raise _err(owner, field, f"{_short(ref)} is a URL: only relative file paths inside the {what}'s folder "
                                 "(or data: URIs) are read")
    absolute = os.path.isabs(text) or text.startswith("\\") or bool(_DRIVE.match(text))
    base = anchor(owner.parent)
    target = os.path.normpath(os.path.join(base, text))
    if absolute:
        if not any(_within(target, a) for a in allowed):
            raise _err(owner, field, f"{_short(ref)} is an absolute path: only paths relative to the {what}'s folder "
                                     "are read (allow other folders with --allow-path DIR)")
        return Path(target)
    if not any(_within(target, r) for r in [base] + allowed):
        raise _err(owner, field, f"{_short(ref)} leaves the {what}'s folder {base} (it resolves to {target}); "
                                 "allow other folders explicitly with --allow-path DIR")
    return Path(target)


def _short(ref: object) -> str:
    s = repr(ref)
    return s if len(s) <= 120 else s[:100] + "...'"


# ----------------------------------------------------------------------------- race-free opens
_O = os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOCTTY", 0)
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)
_DIRECTORY = getattr(os, "O_DIRECTORY", 0)
_O_PATH = getattr(os, "O_PATH", 0)
_HAVE_DIR_FD = os.open in os.supports_dir_fd and bool(_NOFOLLOW) and bool(_DIRECTORY)


def _kind(mode: int) -> str:
    return ("a folder" if stat.S_ISDIR(mode) else "a named pipe" if stat.S_ISFIFO(mode) else
            "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else
            "a symbolic link" if stat.S_ISLNK(mode) else "not a regular file")


def _open_error(owner: str | os.PathLike[str] | None, field: str | None, what: str, path: str | os.PathLike[str], e: OSError, part: str | None = None) -> FormatError:
    if e.errno in (errno.ELOOP, errno.EMLINK) or (e.errno == errno.ENOTDIR and part is not None):
        where = f" ({part!r} is a symbolic link or not a folder)" if part else ""
        return _err(owner, field, f"{what} {str(path)!r} is reached through a symbolic link{where}: links are "
                                  "not followed (a link could point anywhere)")
    return _err(owner, field, f"cannot read {what} {str(path)!r}: {e.strerror or e}")


def _walk(root: str, parts: list[str], path: str | os.PathLike[str], owner: str | os.PathLike[str] | None, field: str | None, what: str) -> int:
    """An ``O_PATH`` (or read-only, non-blocking) descriptor of ``root/parts...``, each component
    opened relative to the previous one with ``O_NOFOLLOW`` (folders with ``O_DIRECTORY``)."""
    try:
        fd = os.open(root, _O | _DIRECTORY)
    except OSError as e:
        raise _open_error(owner, field, what, path, e) from None
    try:
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            flags = (_O_PATH | _NOFOLLOW | getattr(os, "O_CLOEXEC", 0)) if (last and _O_PATH) else \
                (_O | _NOFOLLOW | _NONBLOCK | (0 if last else _DIRECTORY))
            try:
                nfd = os.open(part, flags, dir_fd=fd)
            except OSError as e:
                raise _open_error(owner, field, what, path, e, None if last else part) from None
            os.close(fd)
            fd = nfd
        return fd
    except BaseException:
        os.close(fd)
        raise


def _reopen(pfd: int, st: os.stat_result, parts: list[str], root: str, path: str | os.PathLike[str], owner: str | os.PathLike[str] | None, field: str | None,
            what: str) -> int:
    """A read-only descriptor of the file ``O_PATH`` descriptor ``pfd`` holds (the same inode)."""
    try:
        return os.open(f"/proc/self/fd/{pfd}", _O | _NONBLOCK)
    except OSError:  # no /proc: open the last component again and check it is the same file
        fd = _walk(root, parts[:-1], path, owner, field, what) if len(parts) > 1 else os.open(root, _O | _DIRECTORY)
        try:
            rfd = os.open(parts[-1], _O | _NOFOLLOW | _NONBLOCK, dir_fd=fd)
        except OSError as e:
            raise _open_error(owner, field, what, path, e) from None
        finally:
            os.close(fd)
        st2 = os.fstat(rfd)
        if (st2.st_dev, st2.st_ino) != (st.st_dev, st.st_ino):
            os.close(rfd)
            raise _err(owner, field, f"{what} {str(path)!r} changed while being opened") from None
        return rfd


def open_regular(path: str | os.PathLike[str], max_bytes: int = 1 << 62, owner: str | os.PathLike[str] | None = None, field: str | None = None, what: str = "file") -> int:
    """A read-only descriptor of regular file ``path`` of at most ``max_bytes``, opened race-free.

    Below a confinement root (:func:`add_root`: the folders of the files the user named, the
    folders the user allowed) the path is walked from the root one component at a time with
    ``openat(..., O_NOFOLLOW)``: a symbolic link anywhere below the root, swapped in at any moment,
    is refused.  Elsewhere (a path the user typed) its folder's real path is taken and the file
    itself is opened without following a link (so a file found beside another by name, an SSX
    level's ``.ssh``, cannot be a link out; name a link's target instead of the link).  The last
    component is opened ``O_PATH`` (no open of a device or pipe ever happens) and checked with
    ``fstat``: folders, devices, pipes and sockets are refused before any read.  FormatError names
    ``owner`` (default ``path``) and ``field``.
    """
    owner = path if owner is None else owner
    text = os.fspath(path)
    if "\x00" in text:
        raise _err(owner, field, f"{what} path contains a NUL character")
    a = os.path.normpath(os.path.abspath(text))
    root = _root_of(a)
    if root is None:
        try:  # the user's own folder: its links are the user's; the file itself is not followed, so
            # a file found beside it by name (an SSX level's .ssh / _L.ssh, an .mpf's _head.mpf)
            # cannot be a link out of it
            d = os.path.realpath(os.path.dirname(a))
        except (OSError, ValueError) as e:
            raise _err(owner, field, f"cannot read {what} {text!r}: {e}") from None
        a = os.path.join(d, os.path.basename(a))
        root = _root_of(a) or d
    if not _HAVE_DIR_FD:  # no openat: the last component only
        try:
            fd = os.open(a, _O | _NOFOLLOW | _NONBLOCK)
        except OSError as e:
            raise _open_error(owner, field, what, path, e) from None
        parts = None
    else:
        parts = [p for p in os.path.relpath(a, root).split(os.sep) if p not in ("", ".")]
        if not parts:
            raise _err(owner, field, f"{what} {text!r} is a folder, expected a file")
        fd = _walk(root, parts, path, owner, field, what)
    try:
        st = os.fstat(fd)
        if stat.S_ISLNK(st.st_mode):
            raise _err(owner, field, f"{what} {text!r} is a symbolic link: links are not followed (a link could "
                                     "point anywhere)")
        if not stat.S_ISREG(st.st_mode):
            raise _err(owner, field, f"{what} {text!r} is not a regular file ({_kind(st.st_mode)})")
        if st.st_size > max_bytes:
            raise _err(owner, field, f"{what} {text!r} has {st.st_size} bytes, more than the limit of {max_bytes}")
        if parts is not None and _O_PATH:
            rfd = _reopen(fd, st, parts, root, path, owner, field, what)
            os.close(fd)
            fd = rfd
        return fd
    except BaseException:
        os.close(fd)
        raise


def open_file(path: str | os.PathLike[str], max_bytes: int = 1 << 62, owner: str | os.PathLike[str] | None = None, field: str | None = None,
              what: str = "file") -> io.BufferedReader:
    """:func:`open_regular` as a binary file object (for ``np.load``, PIL, zipfile, tifffile)."""
    raw = io.FileIO(open_regular(path, max_bytes, owner, field, what), "rb", closefd=True)
    raw.name = os.fspath(path)  # readers that report or split the name (tifffile) see the path, not the number
    return io.BufferedReader(raw)


def check_regular(path: str | os.PathLike[str], max_bytes: int, owner: str | os.PathLike[str] | None = None, field: str | None = None, what: str = "file") -> int:
    """Size of ``path`` after checking it is a regular file of at most ``max_bytes``, reached
    without links (opened ``O_PATH`` and ``fstat``-ed; nothing is read)."""
    fd = open_regular(path, max_bytes, owner, field, what)
    try:
        return os.fstat(fd).st_size
    finally:
        os.close(fd)


def read_regular(path: str | os.PathLike[str], max_bytes: int, owner: str | os.PathLike[str] | None = None, field: str | None = None, length: int | None = None,
                 what: str = "file", length_field: str | None = None) -> bytes:
    """The bytes of regular file ``path`` (all of them, or the first ``length``).

    Opened by :func:`open_regular` (no links below a confinement root, devices, pipes, sockets and
    folders refused before any read); files over ``max_bytes`` and files shorter than ``length``
    are refused (FormatError naming ``owner``/``field``).
    """
    owner = path if owner is None else owner
    lfield = length_field or field
    if length is not None:
        if isinstance(length, bool) or not isinstance(length, int) or length < 0:
            raise _err(owner, lfield, f"expected a byte length >= 0, got {length!r}")
        if length > max_bytes:
            raise _err(owner, lfield, f"declares {length} bytes, more than the limit of {max_bytes}")
    fd = open_regular(path, max_bytes if length is None else 1 << 62, owner, field, what)
    try:
        size = os.fstat(fd).st_size
        want = size if length is None else length
        if size < want:
            raise _err(owner, lfield, f"declares {length} bytes but {what} {str(path)!r} has only {size}")
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


def read_reference(owner: str | os.PathLike[str], ref: str, max_bytes: int, allow_paths: Iterable[str | os.PathLike[str]] = (), field: str | None = None,
                   length: int | None = None, what: str = "file", length_field: str | None = None) -> bytes:
    """:func:`resolve_reference` then :func:`read_regular`: the bytes of the file ``ref`` names."""
    f = resolve_reference(owner, ref, allow_paths, field)
    return read_regular(f, max_bytes, owner, field, length, what, length_field)


def confined_file(owner: str | os.PathLike[str], ref: str, allow_paths: Iterable[str | os.PathLike[str]] = (), field: str | None = None, what: str = "file",
                  max_bytes: int = 1 << 62) -> Path:
    """The path of the regular file that ``ref`` (a plain path, not a URI) inside ``owner`` names,
    confined to ``owner``'s folder or a folder the user allowed, reached without links, checked
    (``fstat``) and closed.  Later opens of it (:func:`open_regular`) walk it the same way."""
    f = resolve_reference(owner, ref, allow_paths, field, what="scene" if what == "file" else what)
    check_regular(f, max_bytes, owner, field, what)
    return f


def confined_folder(owner: str | os.PathLike[str], ref: str, allow_paths: Iterable[str | os.PathLike[str]] = (), field: str | None = None) -> Path:
    """The folder ``ref`` inside ``owner`` names (it need not exist yet: an output folder), confined
    like :func:`confined_file`; an existing one must be a folder reached without links."""
    f = resolve_reference(owner, ref, allow_paths, field, what="scene")
    root = _root_of(str(f))
    parts = [p for p in os.path.relpath(f, root).split(os.sep) if p not in ("", ".")] if root else []
    fd = None
    try:
        fd = os.open(root, _O | _DIRECTORY) if root else None
        for part in parts:
            try:
                nfd = os.open(part, _O | _NOFOLLOW | _NONBLOCK | _DIRECTORY, dir_fd=fd)
            except FileNotFoundError:
                break  # created later, by the build
            except OSError as e:
                raise _open_error(owner, field, "folder", f, e, part) from None
            if fd is not None:  # (parts is empty without a root)
                os.close(fd)
            fd = nfd
    finally:
        if fd is not None:
            os.close(fd)
    return f


def decode_data_uri(uri: str, max_bytes: int, owner: str | os.PathLike[str] | None = None, field: str | None = None) -> bytes:
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


def json_depth(obj: Any) -> int:
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


def text_depth(data: str | bytes) -> int:
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


def loads_toml(text: str, path: str | os.PathLike[str] | None, what: str = "TOML file",
               error: Callable[..., Exception] = FormatError) -> dict[str, Any]:
    """``tomllib.loads(text)`` with piste's guards: more than :data:`MAX_TOML_BYTES` characters, nesting
    deeper than :data:`MAX_TOML_DEPTH` (measured before parsing: tomllib recurses) and syntax errors
    raise ``error(path, message, line=...)`` (a scene file's SceneError, a lights file's FormatError);
    ``what`` names the kind of file in the size message."""
    import tomllib  # (imported where used: a bundle render parses no TOML)

    if len(text) > MAX_TOML_BYTES:
        raise error(path, f"{len(text)} characters: more than the limit of {MAX_TOML_BYTES} for a {what}")
    if toml_depth(text) > MAX_TOML_DEPTH:
        raise error(path, f"arrays or tables nested more than {MAX_TOML_DEPTH} deep")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"line (\d+)", msg)
        raise error(path, f"not valid TOML: {msg}", line=int(m.group(1)) if m else None) from None


def loads_json(data: str | bytes, path: str | os.PathLike[str] | None, max_depth: int = MAX_JSON_DEPTH, field: str | None = None) -> Any:
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
