"""The ``__repr__`` and ``__eq__`` that :func:`dataclasses.dataclass` writes, written once for piste's
mutable data classes.

``@dataclass`` compiles a new ``__repr__`` and ``__eq__`` for every class (an ``exec`` each: ~0.05 ms
a method on CPython 3.11), which a fresh process pays for every data class it imports (~3 ms of a
bundle render's start for the ~28 mutable ones).  A class declared
``@dataclass(repr=False, eq=False)`` with :class:`DataMethods` as a base gets the same behaviour from
these shared methods instead: the same ``repr`` text (fields with ``repr=True``, the class's
``__qualname__``, ``...`` for a recursive reference), the same ``==`` (the ``compare=True`` fields as
tuples, only against the very same class, else ``NotImplemented``) and, like any data class with
``eq``, no hash.  A frozen one declared ``@dataclass(frozen=True, repr=False, eq=False)`` with
:class:`FrozenDataMethods` as a base also gets the hash a frozen data class with ``eq`` has (the
tuple of its ``compare`` fields, or those with ``hash=True``); ``@dataclass`` still writes its
``__init__`` and its frozen ``__setattr__`` / ``__delattr__``.

API
---
::

    DataMethods          base class: __repr__, __eq__, __hash__ = None
    FrozenDataMethods    base class of a ``@dataclass(frozen=True, repr=False, eq=False)``: __repr__, __eq__
                         and the field hash ``@dataclass(frozen=True)`` writes
"""

from __future__ import annotations

from dataclasses import fields
from _thread import get_ident
from typing import Any

__all__ = ["DataMethods", "FrozenDataMethods"]

#: the (object id, thread id) pairs whose ``repr`` is being made (a reference back to one shows ``...``)
_RUNNING: set[tuple[int, int]] = set()


class DataMethods:
    """``__repr__`` / ``__eq__`` of a ``@dataclass(repr=False, eq=False)`` subclass, as ``@dataclass``
    would generate them (see the module docstring)."""

    __slots__ = ()

    def __repr__(self) -> str:
        key = (id(self), get_ident())
        if key in _RUNNING:
            return "..."
        _RUNNING.add(key)
        try:
            inner = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self) if f.repr)  # type: ignore[arg-type]
        finally:
            _RUNNING.discard(key)
        return f"{self.__class__.__qualname__}({inner})"

    def __eq__(self, other: Any) -> bool:
        if other.__class__ is self.__class__:
            names = [f.name for f in fields(self) if f.compare]  # type: ignore[arg-type]
            return tuple(getattr(self, n) for n in names) == tuple(getattr(other, n) for n in names)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]


class FrozenDataMethods(DataMethods):
    """:class:`DataMethods` and the hash of a frozen data class with ``eq`` (see the module docstring)."""

    __slots__ = ()

    def __hash__(self) -> int:
        return hash(tuple(getattr(self, f.name) for f in fields(self)  # type: ignore[arg-type]
                          if (f.compare if f.hash is None else f.hash)))
