"""Errors raised by piste.

Every error a user can cause (a bad file, a bad argument) is a :class:`PisteError` subclass whose
message names the file, the field and what was expected.
"""

from __future__ import annotations

import errno
import os


class PisteError(Exception):
    """Base class of every error piste raises on purpose."""


class FormatError(PisteError):
    """A file could not be read: names the file, the line or field, and what was expected."""

    #: the message without the file and field, on the errors :mod:`piste.formats.safe_io` raises
    #: (declared only: other FormatErrors have no such attribute, so ``getattr(e, "reason", ...)``)
    reason: str

    def __init__(self, path: str | os.PathLike[str] | None, message: str, line: int | None = None,
                 field: str | None = None) -> None:
        self.path = str(path) if path is not None else None
        self.line = line
        self.field = field
        where = self.path or "<input>"
        if line is not None:
            where += f", line {line}"
        if field is not None:
            where += f", field {field!r}"
        super().__init__(f"{where}: {message}")


class ValidationError(PisteError):
    """Data is structurally valid but breaks an invariant (NaN, broken topology, ...)."""


class ConfigError(PisteError):
    """A command-line argument or scene description is wrong."""


class RenderError(PisteError):
    """OpenGL could not be set up or a draw failed."""


class MissingExtraError(PisteError):
    """An optional dependency is not installed: names the extra that brings it.

    The CLI prints ``piste demo needs the 'gl' extra: pip install 'piste[gl]'``.
    """

    def __init__(self, extra: str, feature: str, module: str) -> None:
        self.extra = extra
        self.feature = feature
        self.module = module
        super().__init__(f"{feature} needs the '{extra}' extra ({module} is not installed): pip install 'piste[{extra}]'")


class OutputError(PisteError):
    """A file or folder could not be written (unwritable, full disk, ...): names the path.

    Partial files are removed before it is raised (see :mod:`piste.formats.atomic`)."""

    def __init__(self, path: str | os.PathLike[str] | None, message: str) -> None:
        self.path = str(path) if path is not None else None
        super().__init__(f"{self.path or '<output>'}: {message}")


def describe_os_error(exc: OSError, path: str | os.PathLike[str] | None = None) -> str:
    """One line for an OSError: the path it concerns and the system's reason (no traceback)."""
    where = path if path is not None else exc.filename
    reason = exc.strerror or str(exc) or type(exc).__name__
    if exc.errno == errno.ENOSPC:
        reason = "no space left on the device (disk full)"
    elif exc.errno == errno.EDQUOT:
        reason = "disk quota exceeded"
    if exc.filename2 is not None:
        return f"{where} -> {exc.filename2}: {reason}"
    return f"{where}: {reason}" if where is not None else reason
