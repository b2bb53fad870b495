"""argparse types for every number on the command line: finite, in range, or a one-line usage error.

Each factory returns a callable for ``add_argument(type=...)``.  A value that does not parse, is
NaN or infinite, or lies outside its range raises :class:`argparse.ArgumentTypeError`, which
argparse reports as ``piste CMD: error: argument --flag: expected ..., got 'TEXT'`` with exit
status 2 (the flag is named by argparse itself), so no command ever sees a NaN height, a negative
seed or a 1e300 field of view.  The callables carry their range (``lo``, ``hi``, ``kind``) so the
tests can find every numeric flag by walking the parser.

API
---
integer(lo, hi) -> Callable[[str], int]          lo <= v <= hi (either may be None: unbounded)
real(lo, hi, lo_open=False, hi_open=False) -> Callable[[str], float]     finite, in [lo, hi] / (lo, hi)
SIZE, FRAMES, FPS, JOBS, SEED, FRACTION, FOV, COORDINATE       the shared ranges
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

__all__ = ["COORDINATE", "FOV", "FPS", "FRACTION", "FRAMES", "JOBS", "MAX_COORDINATE", "SECONDS", "SEED", "SIZE",
           "WORKERS", "NumberType", "integer", "real"]

#: largest |coordinate| in metres a camera flag takes (the .bpt reader's limit: 100,000 km)
MAX_COORDINATE = 1e8


class NumberType:
    """An argparse ``type``: parses one number and checks it (see the module docstring)."""

    def __init__(self, kind: str, lo: float | None, hi: float | None, lo_open: bool = False, hi_open: bool = False
                 ) -> None:
        self.kind = kind  # "int" or "float"
        self.lo, self.hi = lo, hi
        self.lo_open, self.hi_open = lo_open, hi_open
        self.__name__ = kind  # argparse names the type in some messages

    def _fmt(self, x: float) -> str:
        if self.kind == "int" or (float(x).is_integer() and abs(x) < 1e7):
            return str(int(x))
        return f"{x:g}"

    def expected(self) -> str:
        what = "an integer" if self.kind == "int" else "a finite number"
        if self.lo is not None and self.hi is not None:
            left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
            return f"{what} in {left}{self._fmt(self.lo)}, {self._fmt(self.hi)}{right}"
        if self.lo is not None:
            return f"{what} {'>' if self.lo_open else '>='} {self._fmt(self.lo)}"
        if self.hi is not None:
            return f"{what} {'<' if self.hi_open else '<='} {self._fmt(self.hi)}"
        return what

    def __call__(self, text: str) -> Any:  # an int (kind "int") or a float
        text = str(text)
        value: int | float
        try:
            if self.kind == "int":
                value = int(text.strip(), 10)
            else:
                value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {self.expected()}, got {text[:40]!r}") from None
        if self.kind == "float" and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected {self.expected()}, got {text[:40]!r}")
        too_low = self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo)
        too_high = self.hi is not None and (value >= self.hi if self.hi_open else value > self.hi)
        if too_low or too_high:
            raise argparse.ArgumentTypeError(f"expected {self.expected()}, got {text[:40]!r}")
        return value

    def __repr__(self) -> str:
        return f"NumberType({self.expected()})"


def integer(lo: int | None, hi: int | None) -> Callable[[str], int]:
    """An integer ``lo <= v <= hi`` (decimal digits only: no ``1e3``, no ``0x10``)."""
    return NumberType("int", lo, hi)


def real(lo: float | None, hi: float | None, lo_open: bool = False, hi_open: bool = False) -> Callable[[str], float]:
    """A finite float in ``[lo, hi]`` (``(lo, ...`` with ``lo_open``, ``..., hi)`` with ``hi_open``)."""
    return NumberType("float", lo, hi, lo_open, hi_open)


#: image width or height in pixels
SIZE = integer(16, 8192)
#: frames to render or draw (a million frames: 9 hours of video at 30 fps)
FRAMES = integer(1, 1_000_000)
#: video frame rate
FPS = integer(1, 240)
#: worker processes, 0 = every core
JOBS = integer(0, 1024)
#: worker processes, at least one
WORKERS = integer(1, 1024)
#: a course seed (numpy's seeds are unsigned 32-bit and up; random.Random takes any)
SEED = integer(0, 2**32 - 1)
#: a position along the track, 0..1
FRACTION = real(0.0, 1.0)
#: a vertical field of view in degrees
FOV = real(0.0, 180.0, lo_open=True, hi_open=True)
#: a camera coordinate in metres
COORDINATE = real(-MAX_COORDINATE, MAX_COORDINATE)
#: a duration in seconds (scripted runs: up to a year)
SECONDS = real(0.0, 365 * 86400.0, lo_open=True)


def focus_aperture(text: str) -> tuple[float, float]:
    """``--dof FOCUS_M:APERTURE`` -> ``(focus, aperture)`` metres, each a checked number."""
    focus, sep, aperture = str(text).partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected FOCUS_M:APERTURE (e.g. 8:0.1), got {str(text)[:40]!r}")
    return real(0.0, 1e5, lo_open=True)(focus), real(0.0, 100.0)(aperture)
