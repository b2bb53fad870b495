"""Validation helpers for glTF fields that pygltflib passes through unchecked.

pygltflib keeps whatever the JSON holds (``null``, strings, nested lists) in light, camera and
weight fields; these helpers turn them into numbers or raise a
:class:`~piste.errors.FormatError` naming the file and field (``"red"`` as a colour, ``null`` as a
field of view, ``1e308`` as an intensity).  They also make degenerate but legal transforms safe: a
node scaled to zero has a singular matrix (glTF allows it), whose inverse does not exist.

API
---
number(path, field, v, default=None, lo=-inf, hi=inf, lo_open=False, hi_open=False) -> float
vector(path, field, v, n, default=None, lo=-inf, hi=inf) -> (n,) float64
float_array(v) -> (k,) float64 or None        any nesting of finite numbers, else None
light_fields(path, field, ld) -> dict         checked KHR_lights_punctual light definition
singular(m) -> bool                           a (4, 4) affine matrix with no inverse
rest_inverse(m) -> (4, 4)                     inverse, or identity when singular
normal_matrix(m) -> (3, 3)                    inverse transpose up to a positive factor (cofactors)
MAX_LIGHT_INTENSITY
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError

__all__ = ["number", "vector", "float_array", "light_fields", "singular", "rest_inverse", "normal_matrix",
           "MAX_LIGHT_INTENSITY"]

#: brightest light accepted (candela / lux): the sun is ~1e5 lux; 1e308 would bake infinities
MAX_LIGHT_INTENSITY = 1e9
_LIGHT_TYPES = ("directional", "point", "spot")


def number(path: str | os.PathLike[str], field: str, v: Any, default: float | None = None, lo: float = -math.inf, hi: float = math.inf,
           lo_open: bool = False, hi_open: bool = False) -> float:
    """``v`` as a finite float within ``[lo, hi]`` (open ends with ``lo_open``/``hi_open``)."""
    if v is None:
        if default is None:
            raise FormatError(path, "is missing: expected a number", field=field)
        return float(default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise FormatError(path, f"expected a finite number, got {v!r}", field=field)
    v = float(v)
    if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        lb, hb = "(" if lo_open else "[", ")" if hi_open else "]"
        raise FormatError(path, f"expected a number in {lb}{lo:g}, {hi:g}{hb}, got {v!r}", field=field)
    return v


def vector(path: str | os.PathLike[str], field: str, v: Any, n: int, default: Sequence[float] | None = None, lo: float = -math.inf,
           hi: float = math.inf) -> np.ndarray:
    """``v`` as ``(n,)`` finite floats within ``[lo, hi]``."""
    if v is None and default is not None:
        return np.asarray(default, dtype=np.float64)
    ok = isinstance(v, (list, tuple)) and len(v) == n and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and lo <= x <= hi for x in v)
    if not ok:
        rng = "" if (lo, hi) == (-math.inf, math.inf) else f" in [{lo:g}, {hi:g}]"
        raise FormatError(path, f"expected {n} finite numbers{rng}, got {_short(v)}", field=field)
    return np.asarray(v, dtype=np.float64)


def float_array(v: Any) -> np.ndarray | None:
    """``(k,) float64`` of a (possibly nested) list of finite numbers, or None if it is not one."""
    try:
        a = np.asarray(v, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        return None
    return a if np.all(np.isfinite(a)) else None


def light_fields(path: str | os.PathLike[str], field: str, ld: Any) -> dict[str, Any]:
    """The checked fields of one ``KHR_lights_punctual`` light: name, type, color, intensity, range,
    inner_cone, outer_cone (radians, ``0 <= inner < outer <= pi/2`` as the extension requires)."""
    if not isinstance(ld, dict):
        raise FormatError(path, f"expected a light object, got {_short(ld)}", field=field)
    kind = ld.get("type")
    if kind not in _LIGHT_TYPES:
        raise FormatError(path, f"expected one of {', '.join(_LIGHT_TYPES)}, got {_short(kind)}", field=field + ".type")
    name = ld.get("name")
    if name is not None and not isinstance(name, str):
        raise FormatError(path, f"expected a string, got {_short(name)}", field=field + ".name")
    out = {
        "name": name,
        "type": kind,
        "color": vector(path, field + ".color", ld.get("color"), 3, default=(1.0, 1.0, 1.0), lo=0.0, hi=1e6),
        "intensity": number(path, field + ".intensity", ld.get("intensity"), 1.0, 0.0, MAX_LIGHT_INTENSITY),
        "range": None if ld.get("range") is None else number(path, field + ".range", ld.get("range"), lo=0.0,
                                                             lo_open=True),
    }
    spot = ld.get("spot") if ld.get("spot") is not None else {}
    if not isinstance(spot, dict):
        raise FormatError(path, f"expected an object, got {_short(spot)}", field=field + ".spot")
    out["inner_cone"] = number(path, field + ".spot.innerConeAngle", spot.get("innerConeAngle"), 0.0, 0.0, math.pi / 2)
    out["outer_cone"] = number(path, field + ".spot.outerConeAngle", spot.get("outerConeAngle"), math.pi / 4, 0.0,
                               math.pi / 2, lo_open=True)
    if out["inner_cone"] >= out["outer_cone"]:
        raise FormatError(path, f"innerConeAngle {out['inner_cone']} must be less than outerConeAngle "
                                f"{out['outer_cone']}", field=field + ".spot")
    return out


def singular(m: npt.ArrayLike, eps: float = 1e-12) -> bool:
    """True when the 3x3 part of affine ``m (4, 4)`` has (nearly) no inverse (a node scaled to 0)."""
    a = np.asarray(m, dtype=np.float64)[:3, :3]
    scale = max(float(np.abs(a).max()), 1e-300)
    return not abs(float(np.linalg.det(a / scale))) > eps


def rest_inverse(m: npt.ArrayLike) -> np.ndarray:
    """Inverse of affine ``m (4, 4)``; the identity when ``m`` is singular (a zero-scaled node: its
    meshes are then kept in the node's own space, so skinning with this inverse is still exact)."""
    m = np.asarray(m, dtype=np.float64)
    if singular(m):
        return np.eye(4)
    a = np.linalg.inv(m[:3, :3])
    out = np.eye(4)
    out[:3, :3] = a
    out[:3, 3] = -a @ m[:3, 3]
    return out


def normal_matrix(m: npt.ArrayLike) -> np.ndarray:
    """``(3, 3)`` matrix taking normals through affine ``m``: ``inverse(A).T`` up to a positive
    factor, computed from cofactors so a singular ``A`` (zero scale) gives finite (possibly zero)
    normals instead of a LinAlgError."""
    a = np.asarray(m, dtype=np.float64)[:3, :3]
    c0, c1, c2 = a[:, 0], a[:, 1], a[:, 2]
    cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)
    det = float(np.dot(c0, np.cross(c1, c2)))
    return -cof if det < 0 else cof


def _short(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 80 else s[:70] + "..."
