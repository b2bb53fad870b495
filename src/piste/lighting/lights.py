"""Lights and the one lighting equation shared by the light-map baker and the runtime.

Light types (the talk's "ambient, directional, point and spot lights; negative lights for
shadowing"): :class:`AmbientLight`, :class:`DirectionalLight`, :class:`PointLight`,
:class:`SpotLight`.  Any intensity may be negative: a negative light *darkens* what it lights,
which is how the talk fakes shadows under rocks and in hollows.

The lighting equation
---------------------
For a surface point ``p`` with unit normal ``n``, all colours linear RGB, 1.0 = full white::

    C(p, n) = max(0,  sum_a  I_a c_a
                    + sum_l  I_l c_l  max(0, n . L_l)  A_l(d_l)  S_l  V_l(p) )

* ambient lights ``a`` add ``I_a c_a`` everywhere (no normal, no shadow);
* ``L_l`` is the unit vector from ``p`` towards light ``l`` (for a directional light, minus its
  ``direction``: ``direction`` is the way the light travels); the Lambert factor is clamped at 0 per
  light, so a light never subtracts from surfaces facing away from it, negative lights included;
* ``A_l(d)`` distance attenuation of point and spot lights at distance ``d``:
  ``(1 - min(d / range, 1)) ** falloff`` (``falloff`` 1 = the classic linear ramp to zero at
  ``range``, 2 = a softer, quadratic ramp; 0 = constant inside ``range``); exactly 0 at and beyond
  ``range``; ``A = 1`` for directional lights and for ``range = inf``;
* ``S_l`` spot cone factor: ``smoothstep(cos(outer_angle), cos(inner_angle), -L . D)`` with ``D``
  the spot direction and the angles half-angles of the cone in degrees: 1 inside the inner cone,
  0 outside the outer cone, a smooth Hermite ramp between; ``S = 1`` for other lights;
* ``V_l(p)`` in [0, 1] visibility of the light from ``p`` (shadows), 1 when not computed;
* the sum is clamped below at 0 per channel (negative lights cannot make negative light) and not
  above: values over 1.0 are over-bright, stored half-bright (128 = 1.0) in 8-bit light maps.

:func:`shade` evaluates the equation for ``k`` points at once; :func:`light_terms` gives the
per-light scalar factor ``max(0, n.L) A S`` so a caller (the baker) can cast shadow rays only where
a light actually contributes.  Only ``+ - * / sqrt min max`` are used on per-point data so a point
gets bit-identical lighting wherever it sits in a batch.

TOML lights files (:func:`load_lights`)::

    [[ambient]]
    color = [0.45, 0.55, 0.75]      # linear RGB
    intensity = 0.5

    [[directional]]
    name = "sun"
    direction = [0.3, 0.8, -0.25]   # the way the light travels (normalised on load)
    color = [1.0, 0.85, 0.65]
    intensity = 1.2
    shadows = true                  # cast shadow rays when baking (default true)

    [[point]]
    position = [0.0, 100.0, 20.0]
    color = [1.0, 0.6, 0.3]
    intensity = 0.8
    range = 40.0
    falloff = 1.0

    [[spot]]
    position = [0.0, 0.0, 10.0]
    direction = [0.0, 0.0, -1.0]
    inner_angle = 20.0              # degrees, half-angle
    outer_angle = 35.0
    range = 30.0
    falloff = 1.0
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError, ValidationError
from piste.formats.safe_io import loads_toml
from piste.scene_data import (KIND_OF_LIGHT, LIGHT_KINDS, AmbientLight, AnyLight, DirectionalLight, Lights, PointLight,  # noqa: F401
                              SpotLight)  # (the light family lives in the foundation; re-exported here)

__all__ = [
    "AmbientLight",
    "DirectionalLight",
    "PointLight",
    "SpotLight",
    "Lights",
    "load_lights",
    "loads_lights",
    "dumps_lights",
    "default_lights",
    "light_terms",
    "shade",
]


# --------------------------------------------------------------------------- TOML I/O
_HEADER = re.compile(r"^\s*\[\[\s*([A-Za-z0-9_\-]+)\s*\]\]")
_TABLE = re.compile(r"^\s*\[\s*([A-Za-z0-9_\-.]+)\s*\]")
_KEYLINE = re.compile(r"^\s*([A-Za-z0-9_\-]+)\s*=")


def _find_line(text: str, kind: str, index: int | None = None, key: str | None = None) -> int | None:
    """1-based line of ``[[kind]]`` number ``index`` (or of ``key`` inside it), if it can be found."""
    count = -1
    inside = False
    header_line = None
    for no, line in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(line)
        if m:
            inside = m.group(1) == kind
            if inside:
                count += 1
                if index is None or count == index:
                    header_line = no
                    if key is None:
                        return no
            elif header_line is not None:
                return header_line if key is None else None
            continue
        if _TABLE.match(line):
            inside = False
            continue
        if key is not None and (index is None or count == index) and (inside or kind == ""):
            k = _KEYLINE.match(line)
            if k and k.group(1) == key:
                return no
    return header_line if key is None else header_line


def loads_lights(text: str, path: str | os.PathLike[str] = "<string>") -> Lights:
    """Parse a TOML lights description (see the module docstring).

    Raises :class:`~piste.errors.FormatError` naming the file, line and key on any mistake.
    """
    doc = loads_toml(text, path, "lights file")
    lights = []
    name = doc.pop("name", Path(str(path)).name)
    for kind, items in doc.items():
        if kind not in LIGHT_KINDS:
            raise FormatError(
                path,
                f"unknown light kind {kind!r}: expected [[ambient]], [[directional]], [[point]] or [[spot]]",
                line=_find_line(text, kind) or _find_line(text, "", None, kind),
                field=kind,
            )
        if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
            raise FormatError(
                path, f"expected an array of tables [[{kind}]]", line=_find_line(text, "", None, kind), field=kind
            )
        cls = LIGHT_KINDS[kind]
        allowed = {f.name for f in fields(cls)}
        for i, item in enumerate(items):
            for key in item:
                if key not in allowed:
                    raise FormatError(
                        path,
                        f"unknown key {key!r} in [[{kind}]] number {i + 1}: expected one of {sorted(allowed)}",
                        line=_find_line(text, kind, i, key),
                        field=f"{kind}[{i}].{key}",
                    )
            for key in ("direction", "position"):
                if key in allowed and key not in item and kind != "ambient":
                    raise FormatError(
                        path,
                        f"[[{kind}]] number {i + 1} needs {key!r}",
                        line=_find_line(text, kind, i),
                        field=f"{kind}[{i}].{key}",
                    )
            try:
                lights.append(cls(**item))
            except (ValidationError, TypeError) as exc:
                msg = str(exc)
                bad = next((k for k in item if re.search(rf"\b{k}\b", msg)), None)
                raise FormatError(
                    path,
                    msg,
                    line=_find_line(text, kind, i, bad) if bad else _find_line(text, kind, i),
                    field=f"{kind}[{i}].{bad}" if bad else f"{kind}[{i}]",
                ) from None
    return Lights(tuple(lights), name=str(name))


def load_lights(path: str | os.PathLike[str]) -> Lights:
    """Read a TOML lights file (see the module docstring for the format)."""
    path = Path(path)
    if path.exists() and not path.is_file():  # a folder, device or pipe (which would hang the read)
        raise FormatError(path, "not a regular file")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FormatError(path, "no such file") from None
    except OSError as exc:
        raise FormatError(path, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise FormatError(path, f"not UTF-8 text ({exc})") from None
    return loads_lights(text, path)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    x = float(v)
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(x)


def dumps_lights(lights: Lights) -> str:
    """TOML text that :func:`loads_lights` reads back to equal lights (deterministic)."""
    lines = [f"name = {_toml_value(lights.name)}"]
    for light in lights:
        lines.append("")
        lines.append(f"[[{KIND_OF_LIGHT[type(light)]}]]")
        for f in fields(light):
            lines.append(f"{f.name} = {_toml_value(getattr(light, f.name))}")
    return "\n".join(lines) + "\n"


def default_lights() -> Lights:
    """The default course's lights (``piste/data/default_lights.toml``): a low sun with a coloured
    sky ambient, a few warm point lights along the track and a negative light in a hollow."""
    from importlib.resources import files

    res = files("piste") / "data" / "default_lights.toml"
    return loads_lights(res.read_text(encoding="utf-8"), path=str(res))


# --------------------------------------------------------------------------- the equation
def _dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def light_vectors(light: DirectionalLight | PointLight | SpotLight, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors from each point towards ``light`` and the distances to it.

    Parameters
    ----------
    light : DirectionalLight | PointLight | SpotLight
    positions : (k, 3) float64

    Returns
    -------
    L (k, 3) float64, d (k,) float64 (``inf`` for a directional light).
    """
    positions = np.asarray(positions, dtype=np.float64)
    k = len(positions)
    if isinstance(light, DirectionalLight):
        L = np.broadcast_to(-np.asarray(light.direction), (k, 3))
        return L, np.full(k, np.inf)
    delta = np.asarray(light.position) - positions
    d = np.sqrt(_dot3(delta, delta))
    L = delta / np.where(d > 0.0, d, 1.0)[:, None]
    return L, d


def light_terms(lights: Lights, positions: npt.ArrayLike, normals: npt.ArrayLike) -> np.ndarray:
    """Per-light scalar factor ``max(0, n.L) * A(d) * S`` of every direct light (no colour, no
    intensity, no shadow).

    Parameters
    ----------
    positions, normals : (k, 3) float (normals unit length)

    Returns
    -------
    (k, m) float64, ``m = len(lights.direct)``.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    direct = lights.direct
    out = np.zeros((len(positions), len(direct)))
    for col, light in enumerate(direct):
        L, d = light_vectors(light, positions)
        term = np.maximum(_dot3(normals, L), 0.0)
        if not isinstance(light, DirectionalLight):
            if math.isfinite(light.range):
                x = 1.0 - np.minimum(d / light.range, 1.0)
                if light.falloff == 1.0:
                    att = x
                elif light.falloff == 2.0:
                    att = x * x
                elif light.falloff == 0.0:
                    att = (x > 0.0).astype(np.float64)
                else:
                    att = np.power(x, light.falloff)
                term = term * att
        if isinstance(light, SpotLight):
            cos_axis = -_dot3(L, np.asarray(light.direction)[None, :])
            c_out = math.cos(math.radians(light.outer_angle))
            c_in = math.cos(math.radians(light.inner_angle))
            if c_in > c_out:
                t = np.clip((cos_axis - c_out) / (c_in - c_out), 0.0, 1.0)
                cone = t * t * (3.0 - 2.0 * t)
            else:  # a hard-edged cone
                cone = (cos_axis >= c_in).astype(np.float64)
            term = term * cone
        out[:, col] = term
    return out


def shade(lights: Lights, positions: npt.ArrayLike, normals: npt.ArrayLike, shadow: npt.ArrayLike | None = None) -> np.ndarray:
    """The lighting equation (module docstring) at ``k`` points.

    Parameters
    ----------
    lights : Lights
    positions : (k, 3) float, points on the surface
    normals : (k, 3) float, unit normals
    shadow : None, or (k, m) float
        visibility in [0, 1] of each direct light (``m = len(lights.direct)``, 1 = lit), or
        ``(k,)`` applied to every direct light

    Returns
    -------
    (k, 3) float32 linear RGB, >= 0.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if positions.shape != normals.shape:
        raise ValidationError(f"shade: positions {positions.shape} and normals {normals.shape} differ in shape")
    terms = light_terms(lights, positions, normals)
    if shadow is not None:
        shadow = np.asarray(shadow, dtype=np.float64)
        if shadow.ndim == 1:
            shadow = shadow[:, None]
        terms = terms * shadow
    color = np.broadcast_to(lights.ambient_color(), (len(positions), 3)).copy()
    for col, light in enumerate(lights.direct):
        ic = light.intensity * np.asarray(light.color)
        color += terms[:, col, None] * ic[None, :]
    return np.maximum(color, 0.0).astype(np.float32)
