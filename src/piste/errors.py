"""Errors raised by piste.

Every error a user can cause (a bad file, a bad argument) is a :class:`PisteError` subclass whose
message names the file, the field and what was expected.
"""

from __future__ import annotations


class PisteError(Exception):
    """Base class of every error piste raises on purpose."""


class FormatError(PisteError):
    """A file could not be read: names the file, the line or field, and what was expected."""

    def __init__(self, path, message: str, line: int | None = None, field: str | None = None):
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
