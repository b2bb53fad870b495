"""Scene-level data classes every layer shares: the :class:`Camera` and the light family.

One camera type and one light family serve the scene file (:mod:`piste.world.scene_file`), glTF
import and export (:mod:`piste.formats.gltf`: its ``units`` module converts to and from glTF's
cameras and ``KHR_lights_punctual`` units), the bundle (:mod:`piste.pipeline.bundle_objects`), the
light-map baker (:mod:`piste.lighting`) and the renderer.  They sit in the foundation, below
``formats``, so that the file readers and writers and the cores use the same classes without an
import running back up a layer; :mod:`piste.world.camera` and :mod:`piste.lighting.lights`
re-export them (the same objects) beside the camera and lighting maths.

Conventions: Z up, metres, OpenGL clip space (column vectors, ``clip = P @ V @ [x, y, z, 1]``,
the camera looks down its local -Z); light colours linear RGB, intensities relative (1.0 = full
white, negative = a darkening light; see :mod:`piste.lighting.lights` for the lighting equation).

API
---
::

    Camera                     eye, target, up, fov_y (degrees), near, far, aspect, ortho_height, name
                               (+ view / projection matrices, frustum planes, with_aspect)
    AmbientLight, DirectionalLight, PointLight, SpotLight   frozen, validated on construction
    Lights                     an ordered collection (ambient, directional, point, spot)
    LIGHT_KINDS, KIND_OF_LIGHT {"ambient": AmbientLight, ...} and its inverse
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np

from piste._data import DataMethods, FrozenDataMethods
from piste.errors import ValidationError
from piste.transforms import frustum_planes, look_at, orthographic, perspective

__all__ = ["Camera", "AmbientLight", "DirectionalLight", "PointLight", "SpotLight", "Lights", "LIGHT_KINDS",
           "KIND_OF_LIGHT", "MAX_LIGHT_VALUE", "MAX_COORDINATE"]


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Camera(DataMethods):
    """A pinhole camera (or an orthographic one when ``ortho_height`` is set).

    Attributes
    ----------
    eye, target : (3,) float64 world positions
    up : (3,) float64, the world's up (Z)
    fov_y : vertical field of view in degrees
    near, far : clip distances in metres
    aspect : width / height
    ortho_height : height of the view volume in metres for an orthographic camera, else None
    name : what the scene or file calls it ("" when it has no name)
    """

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    fov_y: float = 60.0
    near: float = 0.5
    far: float = 4000.0
    aspect: float = 640.0 / 448.0
    ortho_height: float | None = None
    name: str = ""

    def __post_init__(self) -> None:
        self.eye = np.asarray(self.eye, dtype=np.float64).reshape(3)
        self.target = np.asarray(self.target, dtype=np.float64).reshape(3)
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3)

    @property
    def forward(self) -> np.ndarray:
        """Unit view direction ``(3,)``."""
        d = self.target - self.eye
        return d / np.linalg.norm(d)

    def view_matrix(self) -> np.ndarray:
        return look_at(self.eye, self.target, self.up)

    def projection_matrix(self) -> np.ndarray:
        if self.ortho_height is not None:
            h = self.ortho_height / 2.0
            w = h * self.aspect
            return orthographic(-w, w, -h, h, self.near, self.far)
        return perspective(self.fov_y, self.aspect, self.near, self.far)

    def view_projection(self) -> np.ndarray:
        """``P @ V``, ``(4, 4) float64``."""
        return self.projection_matrix() @ self.view_matrix()

    def frustum_planes(self) -> np.ndarray:
        """``(6, 4) float64`` inward planes, see :func:`frustum_planes`."""
        return frustum_planes(self.view_projection())

    def with_aspect(self, width: int, height: int) -> "Camera":
        return replace(self, aspect=float(width) / float(height))


#: largest magnitude of a light's intensity or colour component, and of a position coordinate:
#: far beyond any real light (the sun is ~1e5 lux), far below what overflows a float32 light map
MAX_LIGHT_VALUE = 1e6
MAX_COORDINATE = 1e9


def _vec3(value: Any, what: str, limit: float = MAX_COORDINATE) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        arr = None
    if arr is None or arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValidationError(f"{what}: expected 3 finite numbers, got {value!r}")
    if np.abs(arr).max() > limit:
        raise ValidationError(f"{what}: expected numbers within +-{limit:g}, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _unit(value: Any, what: str) -> tuple[float, float, float]:
    v = np.asarray(_vec3(value, what))
    length = float(np.sqrt(v @ v))
    if length <= 0.0:
        raise ValidationError(f"{what}: expected a non-zero direction, got {value!r}")
    if abs(length - 1.0) > 1e-12:  # leave unit vectors bit for bit (TOML round trips exactly)
        v = v / length
    return (float(v[0]), float(v[1]), float(v[2]))


def _finite(value: Any, what: str, limit: float = math.inf) -> float:
    if isinstance(value, (str, bytes)):  # float("1e3") would pass: a light file gives numbers
        raise ValidationError(f"{what}: expected a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValidationError(f"{what}: expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValidationError(f"{what}: expected a finite number, got {value!r}")
    if abs(x) > limit:
        raise ValidationError(f"{what}: expected a number within +-{limit:g}, got {value!r}")
    return x


def _range(value: Any, what: str) -> float:
    x = float(value) if isinstance(value, (int, float)) else _finite(value, what)
    if not x > 0.0:  # also rejects NaN
        raise ValidationError(f"{what}: expected range > 0 (inf for none), got {value!r}")
    return x


def _falloff(value: Any, what: str) -> float:
    x = _finite(value, what)
    if x < 0.0:
        raise ValidationError(f"{what}: expected falloff >= 0, got {value!r}")
    return x


#: each light field's check, in the order they run (the first bad field is the one named)
_FIELD_CHECKS = (
    ("position", lambda v, what: _vec3(v, what)),
    ("direction", _unit),
    ("color", lambda v, what: _vec3(v, what, MAX_LIGHT_VALUE)),
    ("intensity", lambda v, what: _finite(v, what, MAX_LIGHT_VALUE)),
    ("range", _range),
    ("falloff", _falloff),
    ("shadows", lambda v, what: bool(v)),
)


def _check_fields(light: Any, kind: str) -> str:
    """Check and normalise the fields ``light`` (a frozen light) has, naming ``"<kind> light 'name'
    <field>"`` in a ValidationError; returns that ``"<kind> light 'name'"`` prefix."""
    w = f"{kind} light {light.name!r}"
    names = {f.name for f in fields(light)}
    for name, check in _FIELD_CHECKS:
        if name in names:
            object.__setattr__(light, name, check(getattr(light, name), f"{w} {name}"))
    return w


@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class AmbientLight(FrozenDataMethods):
    """Light from everywhere: adds ``intensity * color`` to every point.  ``color (3,)`` linear RGB."""

    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    name: str = ""

    def __post_init__(self) -> None:
        _check_fields(self, "ambient")


@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class DirectionalLight(FrozenDataMethods):
    """A light at infinity (the sun).  ``direction (3,)``: the way the light travels (unit on
    construction); ``shadows``: whether the baker casts shadow rays for it."""

    direction: tuple = (0.0, 0.0, -1.0)
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    shadows: bool = True
    name: str = ""

    def __post_init__(self) -> None:
        _check_fields(self, "directional")


@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class PointLight(FrozenDataMethods):
    """A light at ``position (3,)`` reaching ``range`` model units with attenuation
    ``(1 - d/range) ** falloff``."""

    position: tuple = (0.0, 0.0, 0.0)
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    range: float = math.inf
    falloff: float = 1.0
    shadows: bool = True
    name: str = ""

    def __post_init__(self) -> None:
        _check_fields(self, "point")


@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class SpotLight(FrozenDataMethods):
    """A point light restricted to a cone around ``direction (3,)`` (unit on construction).

    ``inner_angle`` / ``outer_angle``: half-angles of the full-intensity cone and of the cone
    outside which it is dark, degrees, ``0 <= inner <= outer <= 180``."""

    position: tuple = (0.0, 0.0, 0.0)
    direction: tuple = (0.0, 0.0, -1.0)
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    range: float = math.inf
    inner_angle: float = 20.0
    outer_angle: float = 30.0
    falloff: float = 1.0
    shadows: bool = True
    name: str = ""

    def __post_init__(self) -> None:
        w = _check_fields(self, "spot")
        inner = _finite(self.inner_angle, f"{w} inner_angle")
        outer = _finite(self.outer_angle, f"{w} outer_angle")
        if not (0.0 <= inner <= outer <= 180.0):
            raise ValidationError(
                f"{w}: expected 0 <= inner_angle <= outer_angle <= 180 degrees, got {inner} and {outer}"
            )
        object.__setattr__(self, "inner_angle", inner)
        object.__setattr__(self, "outer_angle", outer)


LIGHT_KINDS = {"ambient": AmbientLight, "directional": DirectionalLight, "point": PointLight, "spot": SpotLight}
KIND_OF_LIGHT = {cls: kind for kind, cls in LIGHT_KINDS.items()}
#: any one light of the family
AnyLight = AmbientLight | DirectionalLight | PointLight | SpotLight


@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class Lights(FrozenDataMethods):
    """An ordered collection of lights, kept in canonical order: ambient, directional, point, spot
    lights, each kind in the order given (the order of a TOML file).

    ``ambient``: the ambient lights; ``direct``: every other light, in order (the columns of
    :func:`light_terms` and of the ``shadow`` argument of :func:`shade`).
    """

    lights: tuple = field(default_factory=tuple)
    name: str = "lights"

    def __post_init__(self) -> None:
        lights = tuple(self.lights)
        for i, light in enumerate(lights):
            if type(light) not in KIND_OF_LIGHT:
                raise ValidationError(f"{self.name}: item {i} is {type(light).__name__}, expected a light")
        # canonical order: by kind (ambient, directional, point, spot), then as given
        rank = {cls: r for r, cls in enumerate(LIGHT_KINDS.values())}
        lights = tuple(sorted(lights, key=lambda x: rank[type(x)]))
        object.__setattr__(self, "lights", lights)

    def __iter__(self) -> Iterator[AnyLight]:
        return iter(self.lights)

    def __len__(self) -> int:
        return len(self.lights)

    @property
    def ambient(self) -> tuple:
        return tuple(x for x in self.lights if isinstance(x, AmbientLight))

    @property
    def direct(self) -> tuple:
        return tuple(x for x in self.lights if not isinstance(x, AmbientLight))

    def ambient_color(self) -> np.ndarray:
        """Sum of the ambient terms, ``(3,)`` float64."""
        out = np.zeros(3)
        for a in self.ambient:
            out = out + a.intensity * np.asarray(a.color)
        return out

    def to_dict(self) -> dict:
        """A plain, canonical description: ``{kind: [fields, ...]}`` (used for hashing and TOML)."""
        out: dict = {kind: [] for kind in LIGHT_KINDS}
        for light in self.lights:
            d = asdict(light)
            d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
            out[KIND_OF_LIGHT[type(light)]].append(d)
        return {k: v for k, v in out.items() if v}

    def __add__(self, other: "Lights") -> "Lights":
        return Lights(self.lights + tuple(other.lights), self.name)
