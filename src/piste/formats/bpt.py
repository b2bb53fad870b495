"""Newell's Bézier patch text format (``.bpt``), as used for the Utah teapot.

Layout::

    <patch count>
    3 3                 <- per patch: the degrees in u and v (only bicubic is supported)
    x y z               <- 16 control points, row-major 4x4
    ...
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError
from piste.formats import limits, safe_io
from piste.formats.atomic import write_bytes_atomic

#: largest .bpt read (a patch takes ~400 bytes of text: ~2.6 million patches)
MAX_BPT_BYTES = 1 << 30
_MIN_PATCH_BYTES = 4 + 16 * 6  # "3 3\n" and 16 lines of "0 0 0\n"
#: largest absolute coordinate of a control point: 100,000 km, beyond any map projection's metres (UTM
#: northings stop at 1e7).  Larger values only overflow later (extents, welding tolerances: 1e300
#: once reached scipy as a raw ValueError), so they are refused here, naming the line.
MAX_BPT_COORDINATE = 1e8


def read_bpt(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a ``.bpt`` file.

    Returns
    -------
    (n, 4, 4, 3) float64 control points, ``P[i, j]`` = the ``4*i + j``-th point of a patch.

    Raises
    ------
    FormatError naming the file and line of the first problem.
    """
    path = Path(path)
    if not path.exists():
        raise FormatError(path, "no such file")
    data = safe_io.read_regular(path, MAX_BPT_BYTES)  # regular files only, size-capped, before reading
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(path, f"not a text file ({exc.reason})") from None
    lines = [(no, line.split()) for no, line in enumerate(text.splitlines(), 1) if line.strip()]
    if not lines:
        raise FormatError(path, "empty file: expected a patch count", line=1)
    it = iter(lines)

    def numbers(expected: int, what: str, conv: Callable[[str], Any] = float,
                limit: float | None = None) -> tuple[int, list[Any]]:
        try:
            no, parts = next(it)
        except StopIteration:
            raise FormatError(path, f"unexpected end of file: expected {what}", line=len(text.splitlines()) + 1) from None
        if len(parts) != expected:
            raise FormatError(path, f"expected {what} ({expected} numbers), got {' '.join(parts)!r}", line=no)
        try:
            vals = [conv(p) for p in parts]
        except ValueError:
            raise FormatError(path, f"expected {what}, got {' '.join(parts)!r}", line=no) from None
        if conv is float and not np.all(np.isfinite(vals)):
            raise FormatError(path, f"expected finite {what}, got {' '.join(parts)!r}", line=no)
        if limit is not None and max(abs(v) for v in vals) > limit:
            raise FormatError(path, f"expected {what} within +-{limit:g}, got {' '.join(parts)!r}", line=no)
        return no, vals

    no, (count,) = numbers(1, "the patch count", int)
    if count <= 0:
        raise FormatError(path, f"expected a positive patch count, got {count}", line=no)
    # each patch is at least 17 lines ("3 3" and 16 "x y z"): 100 bytes; check before allocating
    if count > limits.MAX_PATCHES or count > len(data) // _MIN_PATCH_BYTES + 1:  # +1: a truncated file says where
        raise FormatError(path, f"patch count {count} is more than the file's {len(data)} bytes can hold "
                                f"(at least {_MIN_PATCH_BYTES} bytes a patch, at most {limits.MAX_PATCHES} patches)",
                          line=no)
    cp = np.empty((count, 16, 3), dtype=np.float64)
    for p in range(count):
        no, deg = numbers(2, f"the degrees of patch {p} ('3 3')", int)
        if deg != [3, 3]:
            raise FormatError(path, f"patch {p}: only bicubic patches ('3 3') are supported, got {deg}", line=no)
        for k in range(16):
            _, cp[p, k] = numbers(3, f"control point {k} of patch {p} as 'x y z'", limit=MAX_BPT_COORDINATE)
    extra = next(it, None)
    if extra is not None:
        raise FormatError(path, f"trailing data after {count} patches", line=extra[0])
    return cp.reshape(count, 4, 4, 3)


def write_bpt(path: str | os.PathLike[str], control_points: npt.ArrayLike) -> None:
    """Write ``(n, 4, 4, 3)`` control points as a ``.bpt`` file (atomically)."""
    cp = np.asarray(control_points, dtype=np.float64).reshape(-1, 16, 3)
    out = [str(len(cp))]
    for patch in cp:
        out.append("3 3")
        out.extend(" ".join(repr(float(x)) for x in pt) for pt in patch)
    write_bytes_atomic(path, ("\n".join(out) + "\n").encode())
