"""Atomic file output: write to a temporary file beside the target, then rename.

A failure while writing (an unwritable folder, a full disk, a path through a file) removes the
temporary file and raises :class:`~piste.errors.OutputError` naming the target and the reason
(``out/x.piste: no space left on the device (disk full)``), so the user sees one clear line and
never a half-written file.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from piste.errors import OutputError, describe_os_error

__all__ = ["atomic_path", "write_bytes_atomic", "check_writable_folder"]


def _output_error(path: Path, exc: OSError) -> OutputError:
    reason = describe_os_error(exc, path=path).split(": ", 1)[-1]
    where = exc.filename if exc.filename not in (None, "") and not str(exc.filename).startswith(
        str(path.parent / f".{path.name}.")) else path
    return OutputError(where, f"cannot write: {reason}")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; on success rename it over ``path``.

    On an exception the temporary file is removed and ``path`` is left untouched, so a reader
    never sees a half-written file.  OSErrors from creating the folder, from writing the temporary
    file (the body) or from the rename become :class:`~piste.errors.OutputError` naming ``path``.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        import tempfile  # (stdlib, ~1 ms: imported by the first write, not by a process that only reads)

        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
    except OSError as exc:
        raise _output_error(path, exc) from None
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the mode open() would
        try:
            yield Path(tmp)
        except OSError as exc:
            # errors about the temporary file (or with no file: a failed write) are output errors;
            # an OSError about some other file (an input read in the body) passes through unchanged
            if exc.filename in (None, "", tmp, str(tmp)):
                raise _output_error(path, exc) from None
            raise
        try:
            os.replace(tmp, path)
        except OSError as exc:
            raise _output_error(path, exc) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (OutputError naming ``path`` on failure)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def check_writable_folder(folder: str | os.PathLike[str]) -> Path:
    """Create ``folder`` (and its parents) and check a file can be made in it, before a long
    computation whose result would go there; OutputError naming the folder otherwise."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        import tempfile

        fd, probe = tempfile.mkstemp(prefix=".piste-write-check.", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise _output_error(folder, exc) from None
    return folder
