"""The Multitool's ``Instances.json``, ``Splines.json`` and ``Models.json``: read, checked, written
back field for field, and (instances, splines) carried to and from a ``.pbd``'s sections.

Facts (SSX-Library, GPL-3.0, read for facts only: ``JsonFiles/Tricky/InstanceJsonHandler.cs``,
``SplineJsonHandler.cs``, ``ModelJsonHandler.cs``, the export and rebuild in
``JsonFiles/TrickyLevelInterface.cs``, the records in ``FileHandlers/LevelFiles/Tricky/PS2/
PBDHandler.cs``, ``Internal/Utilities/BezierUtil.cs``, ``LineStrip.cs``, ``ArrayConv.cs``):

The JSON files are Json.NET serialisations of C# structs: each object's keys in the struct's
declaration order (:data:`INSTANCE_SCHEMA`, :data:`SPLINE_SCHEMA`, :data:`MODEL_SCHEMA`), floats
as float32 (written in their shortest float32 form; ``"NaN"``, ``"Infinity"``, ``"-Infinity"``
for the non-finite ones), ints signed 32-bit, a key the file leaves out is the C# default (0,
false, null) and a key piste does not know is ignored (as Json.NET does).  piste keeps every known
key of every object and writes it back in that order, so a file the Multitool wrote comes back
field for field equal (:func:`instances_json` of :func:`instances_from_json`, and likewise).

* **Instances.json** ``{"Instances": [...]}``: a model placed in the level.  ``Location[3]``
  (game units, centimetres), ``Rotation[4]`` (a quaternion ``x, y, z, w``), ``Scale[3]``: the
  Multitool's ``Matrix4x4.Decompose`` of the record's matrix, and on rebuild ``CreateScale(S) *
  CreateFromQuaternion(R)`` with the translation put in: row vectors, ``world = [x y z 1] @ M``
  (:func:`compose_rows`; :meth:`MtInstances.matrices` gives piste's column form).  Four light
  directions and four light colours (``Vector4`` each: the talk's *1 ambient + 3 directional
  lights*), ``ModelID`` (an index into ``Models.json`` / the level's models), ``PrevInstance``,
  ``NextInstance``, six unknown ints, ``Hash`` (the instance's entry in the hash section's
  instance list) - these live in the ``.pbd``'s 256-byte instance record (:data:`INSTANCE_DTYPE`).
  ``LTGState`` (the ``.ltg``), ``IncludeSound``/``Sounds`` (the ``.adl``) and the object
  properties ``U0`` ... ``U8``, ``Visable``, ``PlayerCollision``, ``CollsionModelPaths`` ... (the
  ``.ssf``) live in files piste does not read or write: they are kept in the JSON round trip but
  a ``.pbd`` does not hold them (a project exported from a ``.pbd`` has their defaults, as the
  Multitool's own export has when its ``.ssf`` comes up short).  ``InstanceName`` lives in the
  ``.map``: piste writes the Multitool's fallback ``Instance_<i>``.
* **Splines.json** ``{"Splines": [...]}``: ``SplineName``, ``U0``, ``U1``, ``SplineStyle`` (the
  ``.ssf``'s spline entry: not in the ``.pbd``, kept in the JSON round trip, 0 from a ``.pbd``),
  ``Segments`` of ``Points[4][3]``: each segment a cubic Bézier's raw control points in game
  units.  In the ``.pbd`` a spline is a 40-byte record (:data:`SPLINE_DTYPE`) over a run of
  128-byte segments (:data:`SEGMENT_DTYPE`) holding the power basis ``P = M R`` stored reversed
  (highest power first, the constant term with w = 1), an arc-length cubic, neighbour links,
  bounds, a length and the length before it.  The Multitool rebuilds a segment as
  :func:`segment_records` does: bounds of the four raw points, the length is the *control
  polygon's* (``LineStrip.Distance``), ``Unknown32`` = 4311823, a spline's ``Unknown1`` = 0 and
  ``Unknown2`` = -1, and the four coefficients are the least-squares cubic ``t(s)`` of the curve
  parameter against the arc length ``s`` in **metres** over 200 samples, highest power first
  (``BezierUtil.CalcCoefficients``).  The Multitool solves the normal equations in float32 by
  Gaussian elimination, piste the least-squares problem in float64 (a pseudo-inverse): on random
  segments of 5-80 m the coefficients differ by 0.1 % (median) to 7 % (worst), the fitted
  ``t(s)`` by at most 1.2e-4, so piste's bytes are not the Multitool's.  piste writes a segment's record only where its points changed (unchanged
  segments keep their stored bytes, so a retail level's own coefficients survive a round trip).
  :meth:`MtSplines.polyline` evaluates a spline as piste's centreline points (metres).
* **Models.json** ``{"Models": [...]}``: a model is ``ModelName``, ``Unknown3``, ``AnimTime`` and
  ``ModelObjects``, each an object with ``ParentID``, ``Flags``, an optional ``Animation`` (six
  floats, ``AnimationAction``, entries of six-float maths), ``MeshData`` (``MeshPath``: a
  ``Meshes/*.obj`` file, ``MaterialID``: an index into ``Materials.json``), an optional matrix
  (``Position``/``Rotation``/``Scale`` with ``IncludeMatrix``).  It is read into a typed,
  checked record (:class:`MtModels`) and written back unchanged, **not** mapped to piste's object
  kinds: a model is meshes (``Meshes/*.obj``) with materials (``Materials.json``) that the
  Multitool compiles into the ``.pbd``'s model, material-block and mesh-data sections, which piste
  neither decodes nor encodes; piste's own object kinds (tree, sign, rock, rail) are procedural
  meshes with no file behind them.  For the same reason a project exported from a ``.pbd`` has
  no ``Models.json``.

API
---
instances_from_json(doc, path) -> MtInstances;  instances_json(MtInstances) -> dict
splines_from_json(doc, path) -> MtSplines;      splines_json(MtSplines) -> dict
models_from_json(doc, path) -> MtModels;        models_json(MtModels) -> dict
instances_from_pbd(pbd) -> MtInstances;          splines_from_pbd(pbd) -> MtSplines
instances_from_placements(matrix, model) -> MtInstances   piste's placed objects (metres) -> instances
MtInstances.placements() -> names, model, (k, 4, 4) matrices (metres);  MtSplines.polyline(i)
instances_in_place(pbd, data, instances, path) / splines_in_place(pbd, data, splines, path)
spline_sections(splines) -> {"splines": ..., "spline_segments": ...} for synth.pbd_bytes
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError
from piste.formats.ssx.pbd import GAME_SCALE, HEADER_SIZE, M as BEZIER_TO_POWER, M_INV as POWER_TO_BEZIER, Pbd

__all__ = [
    "INSTANCE_DTYPE", "SPLINE_DTYPE", "SEGMENT_DTYPE", "INSTANCE_SCHEMA", "SPLINE_SCHEMA", "MODEL_SCHEMA",
    "MtInstances", "MtSplines", "MtModels", "instances_from_json", "instances_json", "splines_from_json",
    "splines_json", "models_from_json", "models_json", "instances_from_pbd", "splines_from_pbd",
    "instances_in_place", "splines_in_place", "spline_sections", "segment_records", "compose_rows",
    "decompose_rows", "instances_from_placements", "INSTANCES_JSON", "SPLINES_JSON", "MODELS_JSON",
]

INSTANCES_JSON = "Instances.json"
SPLINES_JSON = "Splines.json"
MODELS_JSON = "Models.json"
#: most objects (instances, splines, segments, models, model objects...) one file may hold
MAX_ITEMS = 1_000_000
#: the Multitool's rebuild writes this into every segment's last field
SEGMENT_UNKNOWN32 = 4311823
#: samples of the Multitool's arc-length fit
FIT_SAMPLES = 200

#: one 256-byte instance record (PBDHandler.cs: matrix, light-direction matrix whose columns are
#: LightVector1..3 and AmbentLightVector, four colours, ids, bounds, unknown ints)
INSTANCE_DTYPE = np.dtype([
    ("matrix", "<f4", (4, 4)),  # row vectors: world = [x y z 1] @ matrix
    ("light_matrix", "<f4", (4, 4)),  # column j = light vector j
    ("light_colour", "<f4", (4, 4)),  # LightColour1..3, AmbentLightColour
    ("model_id", "<i4"), ("prev", "<i4"), ("next", "<i4"),
    ("lowest", "<f4", (3,)), ("highest", "<f4", (3,)),
    ("unknown26", "<i4"), ("unknown27", "<i4"), ("unknown28", "<i4"), ("model_id2", "<i4"),
    ("unknown30", "<i4"), ("unknown31", "<i4"), ("unknown32", "<i4"),
])
assert INSTANCE_DTYPE.itemsize == 256
#: one 40-byte spline record
SPLINE_DTYPE = np.dtype([("lowest", "<f4", (3,)), ("highest", "<f4", (3,)), ("unknown1", "<i4"),
                         ("segment_count", "<i4"), ("segment_start", "<i4"), ("unknown2", "<i4")])
assert SPLINE_DTYPE.itemsize == 40
#: one 128-byte spline segment record
SEGMENT_DTYPE = np.dtype([
    ("power", "<f4", (4, 4)),  # Point4, Point3, Point2, ControlPoint: P3, P2, P1, P0 (w 0, 0, 0, 1)
    ("coefficients", "<f4", (4,)),  # t(s), s in metres: highest power first
    ("prev", "<i4"), ("next", "<i4"), ("spline", "<i4"),
    ("lowest", "<f4", (3,)), ("highest", "<f4", (3,)),
    ("length", "<f4"), ("length_before", "<f4"), ("unknown32", "<i4"),
])
assert SEGMENT_DTYPE.itemsize == 128

# ----------------------------------------------------------------------------- schemas
# (key, kind, required); kinds: "s" string or null, "f" float32, "i" int32, "b" bool,
# ("v", n) n floats (null allowed unless required), ("m", r, c) r x c floats, "ss" strings or null,
# ("l", schema) a list of objects (null allowed unless required), ("o", schema) an object or null
_SOUND = (("U0", "i", False), ("SoundIndex", "i", False), ("U2", "f", False), ("U3", "f", False),
          ("U4", "f", False), ("U5", "f", False), ("U6", "f", False))
#: InstanceJsonHandler.InstanceJson, in declaration order
INSTANCE_SCHEMA = (
    ("InstanceName", "s", False),
    ("Location", ("v", 3), True), ("Rotation", ("v", 4), True), ("Scale", ("v", 3), True),
    ("LightVector1", ("v", 4), True), ("LightVector2", ("v", 4), True), ("LightVector3", ("v", 4), True),
    ("AmbentLightVector", ("v", 4), True),
    ("LightColour1", ("v", 4), True), ("LightColour2", ("v", 4), True), ("LightColour3", ("v", 4), True),
    ("AmbentLightColour", ("v", 4), True),
    ("ModelID", "i", False), ("PrevInstance", "i", False), ("NextInstance", "i", False),
    ("UnknownInt26", "i", False), ("UnknownInt27", "i", False), ("UnknownInt28", "i", False),
    ("UnknownInt30", "i", False), ("UnknownInt31", "i", False), ("UnknownInt32", "i", False),
    ("LTGState", "i", False), ("Hash", "i", False), ("IncludeSound", "b", False),
    ("Sounds", ("o", (("CollisonSound", "i", False), ("ExternalSounds", ("l", _SOUND), False))), False),
    ("U0", "f", False), ("PlayerBounceAmmount", "f", False), ("U2", "i", False), ("Visable", "b", False),
    ("PlayerCollision", "b", False), ("PlayerBounce", "b", False), ("Unknown241", "b", False),
    ("UVScroll", "b", False), ("SurfaceType", "i", False), ("CollsionMode", "i", False),
    ("CollsionModelPaths", "ss", False), ("EffectSlotIndex", "i", False), ("PhysicsIndex", "i", False),
    ("U8", "i", False),
)
#: SplineJsonHandler.SplineJson
SPLINE_SCHEMA = (("SplineName", "s", False), ("U0", "i", False), ("U1", "i", False), ("SplineStyle", "i", False),
                 ("Segments", ("l", (("Points", ("m", 4, 3), True),)), True))
_MATHS = tuple((f"Value{i}", "f", False) for i in range(1, 7))
_ANIMATION = tuple((f"U{i}", "f", False) for i in range(1, 7)) + (
    ("AnimationAction", "i", False), ("AnimationEntries", ("l", (("AnimationMaths", ("l", _MATHS), False),)), False))
_OBJECT = (("ObjectName", "s", False), ("ParentID", "i", False), ("Flags", "i", False),
           ("Animation", ("o", _ANIMATION), False),
           ("MeshData", ("l", (("MeshPath", "s", False), ("MaterialID", "i", False))), True),
           ("Position", ("v", 3), False), ("Rotation", ("v", 4), False), ("Scale", ("v", 3), False),
           ("IncludeAnimation", "b", False), ("IncludeMatrix", "b", False))
#: ModelJsonHandler.ModelJson
MODEL_SCHEMA = (("ModelName", "s", False), ("Unknown3", "i", False), ("AnimTime", "f", False),
                ("ModelObjects", ("l", _OBJECT), True))

_NONFINITE = {"NaN": float("nan"), "Infinity": float("inf"), "-Infinity": float("-inf")}
_F32_MAX = float(np.finfo(np.float32).max)


def _f32(v: float) -> float:
    """A float32 value as the Python float of its shortest float32 form (what Json.NET writes)."""
    x = np.float32(v)
    return float(str(x)) if np.isfinite(x) else float(x)


def _f32s(a: npt.ArrayLike) -> np.ndarray:
    """:func:`_f32` of a whole array at once, ``(...)`` float64 (numpy's shortest float32 strings,
    parsed back: both in C)."""
    with np.errstate(over="ignore"):  # past float32's range: inf, as a float32 record would hold it
        return np.asarray(a, np.float32).astype(str).astype(np.float64)


def _out_float(v: float) -> float | str:
    if v != v:
        return "NaN"
    if v in (_INF, -_INF):
        return "Infinity" if v > 0 else "-Infinity"
    return v


_INF = float("inf")


class _Reader:
    """Checks a parsed JSON document against a schema; errors name the file, the object and the key."""

    def __init__(self, path: str | os.PathLike[str] | None) -> None:
        self.path = path
        self.count = 0
        self.pending: list[tuple[dict, str]] = []  # (dict, key) of floats still to round to float32, done at once in top()
        self.lists: list[list] = []  # lists of floats still to round

    def fail(self, where: str, key: str, msg: str) -> None:
        raise FormatError(self.path, f"{where}: {key} {msg}", field=key)

    def number(self, v: Any, where: str, key: str) -> float:
        if isinstance(v, str) and v in _NONFINITE:
            return _NONFINITE[v]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (
                abs(v) > _F32_MAX and not (isinstance(v, float) and v in (_INF, -_INF))):  # a huge int: no isfinite
            self.fail(where, key, f"must be a number (float32), got {v!r:.40}")
        return float(v)

    def numbers(self, v: Any, where: str, key: str) -> list:
        """A list of float32 values (rounded later, in top())."""
        if all(type(x) is float and -_F32_MAX <= x <= _F32_MAX for x in v):  # the usual case, at C speed
            out = list(v)
        else:
            out = [self.number(x, where, key) for x in v]
        self.lists.append(out)
        return out

    def integer(self, v: Any, where: str, key: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or not -2**31 <= v < 2**31:
            self.fail(where, key, f"must be a 32-bit signed integer, got {v!r:.40}")
        return v

    def items(self, v: Any, where: str, key: str, required: bool) -> list | None:
        if v is None and not required:
            return None
        if not isinstance(v, list):
            self.fail(where, key, f"must be a list, got {type(v).__name__}")
        self.count += len(v)
        if self.count > MAX_ITEMS:
            self.fail(where, key, f"more than the limit of {MAX_ITEMS} entries in one file")
        return v

    def value(self, v: Any, kind: Any, where: str, key: str, required: bool) -> Any:
        if kind == "s":
            if v is None or isinstance(v, str):
                return v
            self.fail(where, key, f"must be a string, got {type(v).__name__}")
        if kind == "f":
            return self.number(v, where, key)  # rounded in obj()
        if kind == "i":
            return self.integer(v, where, key)
        if kind == "b":
            if isinstance(v, bool):
                return v
            self.fail(where, key, f"must be true or false, got {v!r:.40}")
        if kind == "ss":
            v = self.items(v, where, key, False)
            if v is None:
                return None
            if not all(isinstance(s, str) for s in v):
                self.fail(where, key, "must be a list of strings")
            return list(v)
        tag = kind[0]
        if tag == "v":
            if v is None and not required:
                return None
            if not isinstance(v, list) or len(v) != kind[1]:
                self.fail(where, key, f"must be a list of {kind[1]} numbers, got {v!r:.60}")
            return self.numbers(v, where, key)
        if tag == "m":
            r, c = kind[1], kind[2]
            if not isinstance(v, list) or len(v) != r or not all(isinstance(row, list) and len(row) == c for row in v):
                self.fail(where, key, f"must be {r} lists of {c} numbers, got {v!r:.60}")
            return [self.numbers(row, where, key) for row in v]
        if tag == "o":
            if v is None:
                return None
            return self.obj(v, kind[1], f"{where}: {key}")
        if tag == "l":
            v = self.items(v, where, key, required)
            if v is None:
                return None
            return [self.obj(x, kind[1], f"{where}: {key}[{i}]") for i, x in enumerate(v)]
        raise AssertionError(kind)

    def obj(self, d: Any, schema: Any, where: str) -> dict:
        if not isinstance(d, dict):
            raise FormatError(self.path, f"{where}: expected an object, got {type(d).__name__}", field=where)
        out = {}
        for key, kind, required in schema:
            v = d.get(key)
            if v is None and required:
                self.fail(where, key, "is required")
            if v is None and kind in ("f", "i"):
                v = 0
            elif v is None and kind == "b":
                v = False
            out[key] = self.value(v, kind, where, key, required)
            if kind == "f":
                self.pending.append((out, key))
        return out

    def top(self, doc: Any, key: str, schema: Any, what: str) -> list:
        items = doc.get(key, []) if isinstance(doc, dict) else doc  # {} is none, as the Multitool reads it
        if items is None:
            items = []
        if not isinstance(items, list):
            raise FormatError(self.path, f"expected a list of {what} (or {{\"{key}\": [...]}})", field=key)
        if len(items) > MAX_ITEMS:
            raise FormatError(self.path, f"{len(items)} {what}: more than the limit of {MAX_ITEMS}", field=key)
        out = [self.obj(d, schema, f"{what[:-1]} {i}") for i, d in enumerate(items)]
        # every float rounded to float32 (its shortest form) at once
        flat = [c[k] for c, k in self.pending]
        for lst in self.lists:
            flat.extend(lst)
        vals = _f32s(flat).tolist() if flat else []
        for (c, k), v in zip(self.pending, vals):
            c[k] = v
        pos = len(self.pending)
        for lst in self.lists:
            lst[:] = vals[pos:pos + len(lst)]
            pos += len(lst)
        self.pending, self.lists = [], []
        return out


def _finite(v: list) -> bool:
    return all(-_F32_MAX <= x <= _F32_MAX for x in v)


def _write(items: list, schema: Any) -> list:
    """Checked items back as JSON values (floats in their float32 form, non-finite as strings)."""
    def val(v: Any, kind: Any) -> Any:
        if v is None:
            return None
        if kind == "f":
            return _out_float(v)
        if isinstance(kind, tuple):
            if kind[0] == "v":
                return v if _finite(v) else [_out_float(x) for x in v]
            if kind[0] == "m":
                return [row if _finite(row) else [_out_float(x) for x in row] for row in v]
            if kind[0] == "o":
                return obj(v, kind[1])
            if kind[0] == "l":
                return [obj(x, kind[1]) for x in v]
        return v

    def obj(d: dict, sch: Any) -> dict:
        return {key: val(d.get(key), kind) for key, kind, _ in sch}

    return [obj(d, schema) for d in items]


# ----------------------------------------------------------------------------- matrices
def compose_rows(location: npt.ArrayLike, rotation: npt.ArrayLike, scale: npt.ArrayLike) -> np.ndarray:
    """The Multitool's instance matrix, ``(k, 4, 4)`` float64 in row-vector form (``world = [x y z
    1] @ M``): ``CreateScale(scale) * CreateFromQuaternion(rotation)``, translation ``location``.
    ``location (k, 3)``, ``rotation (k, 4)`` quaternions ``x, y, z, w`` (used as given, not
    normalised, as ``CreateFromQuaternion`` does), ``scale (k, 3)``."""
    t = np.asarray(location, np.float64).reshape(-1, 3)
    q = np.asarray(rotation, np.float64).reshape(-1, 4)
    s = np.asarray(scale, np.float64).reshape(-1, 3)
    x, y, z, w = q.T
    r = np.empty((len(q), 3, 3))  # row form of the rotation (System.Numerics CreateFromQuaternion)
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y + z * w)
    r[:, 0, 2] = 2 * (x * z - y * w)
    r[:, 1, 0] = 2 * (x * y - z * w)
    r[:, 1, 1] = 1 - 2 * (z * z + x * x)
    r[:, 1, 2] = 2 * (y * z + x * w)
    r[:, 2, 0] = 2 * (x * z + y * w)
    r[:, 2, 1] = 2 * (y * z - x * w)
    r[:, 2, 2] = 1 - 2 * (y * y + x * x)
    out = np.zeros((len(q), 4, 4))
    out[:, :3, :3] = s[:, :, None] * r
    out[:, 3, :3] = t
    out[:, 3, 3] = 1.0
    return out


def decompose_rows(matrix: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(location (k, 3), rotation (k, 4) x, y, z, w, scale (k, 3))`` of row-form matrices ``(k, 4,
    4)``, float64: scale the rows' lengths (all three negated for a mirroring matrix, so the rest
    is a proper rotation), the rotation's quaternion by the trace / largest-diagonal branches of
    ``CreateFromRotationMatrix``; ``compose_rows`` of the result gives the matrix back (to rounding).
    For a mirroring matrix ``Matrix4x4.Decompose`` may split the signs between scale and rotation
    another way (the same matrix, other JSON numbers); rotations and positive scales agree."""
    with np.errstate(all="ignore"):  # a NaN / huge matrix decomposes into NaN / inf, silently
        return _decompose_rows(matrix)


def _decompose_rows(matrix: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body of :func:`decompose_rows`."""
    m = np.asarray(matrix, np.float64).reshape(-1, 4, 4)
    lin = m[:, :3, :3]
    s = np.linalg.norm(lin, axis=2)
    s = np.where(np.linalg.det(lin)[:, None] < 0, -s, s)
    safe = np.where(s == 0, 1.0, s)
    r = np.where((s == 0)[:, :, None], np.eye(3), lin / safe[:, :, None])
    m11, m12, m13 = r[:, 0, 0], r[:, 0, 1], r[:, 0, 2]
    m21, m22, m23 = r[:, 1, 0], r[:, 1, 1], r[:, 1, 2]
    m31, m32, m33 = r[:, 2, 0], r[:, 2, 1], r[:, 2, 2]
    trace = m11 + m22 + m33
    q = np.zeros((len(m), 4))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.sqrt(np.maximum(trace + 1, 0))  # trace > 0: w largest
        inv = 0.5 / a
        qa = np.stack([(m23 - m32) * inv, (m31 - m13) * inv, (m12 - m21) * inv, a * 0.5], 1)
        b = np.sqrt(np.maximum(1 + m11 - m22 - m33, 0))  # x largest
        ib = 0.5 / b
        qb = np.stack([0.5 * b, (m12 + m21) * ib, (m13 + m31) * ib, (m23 - m32) * ib], 1)
        c = np.sqrt(np.maximum(1 + m22 - m11 - m33, 0))  # y largest
        ic = 0.5 / c
        qc = np.stack([(m21 + m12) * ic, 0.5 * c, (m32 + m23) * ic, (m31 - m13) * ic], 1)
        d = np.sqrt(np.maximum(1 + m33 - m11 - m22, 0))  # z largest
        i_d = 0.5 / d
        qd = np.stack([(m31 + m13) * i_d, (m32 + m23) * i_d, 0.5 * d, (m12 - m21) * i_d], 1)
    use_a = trace > 0
    use_b = ~use_a & (m11 >= m22) & (m11 >= m33)
    use_c = ~use_a & ~use_b & (m22 > m33)
    q = np.where(use_a[:, None], qa, np.where(use_b[:, None], qb, np.where(use_c[:, None], qc, qd)))
    q = np.where(np.isfinite(q), q, 0.0)
    return m[:, 3, :3].copy(), q, s


# ----------------------------------------------------------------------------- records
@dataclass
class MtInstances:
    """``Instances.json`` as read: ``items`` one dict per instance, keys in :data:`INSTANCE_SCHEMA`
    order, values checked (floats float32, ints int32)."""

    items: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.items)

    def _vec(self, key: str, n: int) -> np.ndarray:
        return np.array([d[key] for d in self.items], np.float64).reshape(len(self), n)

    @property
    def names(self) -> list:
        return [d["InstanceName"] if d["InstanceName"] is not None else f"Instance_{i}"
                for i, d in enumerate(self.items)]

    @property
    def location(self) -> np.ndarray:
        """``(k, 3)`` float64 game units."""
        return self._vec("Location", 3)

    @property
    def rotation(self) -> np.ndarray:
        """``(k, 4)`` float64 quaternions ``x, y, z, w``."""
        return self._vec("Rotation", 4)

    @property
    def scale(self) -> np.ndarray:
        return self._vec("Scale", 3)

    @property
    def model_id(self) -> np.ndarray:
        """``(k,)`` int64 index into the level's models."""
        return np.array([d["ModelID"] for d in self.items], np.int64)

    @property
    def hash(self) -> np.ndarray:
        return np.array([d["Hash"] for d in self.items], np.int64)

    def matrices(self, scale: float = GAME_SCALE) -> np.ndarray:
        """Object -> world matrices ``(k, 4, 4)`` float64 in piste's column form (``p' = M @ p``),
        translation times ``scale`` (default: game centimetres -> metres; the linear part is the
        Multitool's scale x rotation, to apply to a model converted at the same scale)."""
        m = compose_rows(self.location, self.rotation, self.scale).transpose(0, 2, 1).copy()
        m[:, :3, 3] *= scale
        return m

    def placements(self, scale: float = GAME_SCALE) -> dict:
        """The placed objects as piste's world objects take them: ``{"names": [k], "model":
        (k,) int64, "matrix": (k, 4, 4) float64 object -> world, metres}``."""
        return {"names": self.names, "model": self.model_id, "matrix": self.matrices(scale)}


@dataclass
class MtSplines:
    """``Splines.json`` as read: ``items`` one dict per spline (:data:`SPLINE_SCHEMA` order)."""

    items: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.items)

    def points(self, i: int) -> np.ndarray:
        """Spline ``i``'s raw Bézier control points, ``(segments, 4, 3)`` float64 game units."""
        return np.array([s["Points"] for s in self.items[i]["Segments"]], np.float64).reshape(-1, 4, 3)

    def polyline(self, i: int, samples: int = 8, scale: float = GAME_SCALE) -> np.ndarray:
        """Spline ``i`` evaluated ``samples`` times a segment (its last point once), ``(segments *
        samples + 1, 3)`` float64, times ``scale`` (default metres): a centreline for piste."""
        p = self.points(i)
        t = np.linspace(0.0, 1.0, samples + 1)[:-1]
        basis = np.stack([(1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2, t ** 3], 1)  # (s, 4)
        pts = np.einsum("sk,nkc->nsc", basis, p).reshape(-1, 3)
        return np.concatenate([pts, p[-1:, 3]]) * scale


@dataclass
class MtModels:
    """``Models.json`` as read, a typed record written back unchanged (see the module docstring
    for why it is not mapped to piste's object kinds): ``items`` one dict per model
    (:data:`MODEL_SCHEMA` order)."""

    items: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.items)

    @property
    def mesh_paths(self) -> list:
        """Every ``MeshPath`` (a ``Meshes/`` file name), in order of appearance."""
        return [m["MeshPath"] for d in self.items for o in d["ModelObjects"] for m in o["MeshData"]]


def instances_from_json(doc: Any, path: str | os.PathLike[str] | None) -> MtInstances:
    """A parsed ``Instances.json`` (``{"Instances": [...]}`` or a bare list) checked (FormatError
    naming the instance and the key).  Non-finite placements are read (a ``.pbd``'s own NaNs come
    back as they were) and refused only where piste must build a matrix of them
    (:func:`instances_in_place`)."""
    return MtInstances(_Reader(path).top(doc, "Instances", INSTANCE_SCHEMA, "instances"))


def instances_json(inst: MtInstances) -> dict:
    return {"Instances": _write(inst.items, INSTANCE_SCHEMA)}


def splines_from_json(doc: Any, path: str | os.PathLike[str] | None) -> MtSplines:
    """A parsed ``Splines.json`` checked: every spline needs at least one segment (the Multitool's
    rebuild reads segment 0).  Non-finite points are read (a level's own come back as stored) and
    refused where piste must build a segment of them (:func:`spline_sections`,
    :func:`splines_in_place`)."""
    r = _Reader(path)
    items = r.top(doc, "Splines", SPLINE_SCHEMA, "splines")
    for i, d in enumerate(items):
        if not d["Segments"]:
            r.fail(f"spline {i}", "Segments", "must hold at least one segment")
    return MtSplines(items)


def _finite_points(raw: np.ndarray, path: str | os.PathLike[str] | None, i: int, which: np.ndarray | None = None) -> None:
    bad = ~np.isfinite(raw).reshape(len(raw), -1).all(1)
    if which is not None:
        bad &= which
    if bad.any():
        raise FormatError(path, f"spline {i}: segment {int(np.argmax(bad))}: Points must be finite numbers to build "
                                "the segment", field="Points")


def splines_json(spl: MtSplines) -> dict:
    return {"Splines": _write(spl.items, SPLINE_SCHEMA)}


def models_from_json(doc: Any, path: str | os.PathLike[str] | None) -> MtModels:
    return MtModels(_Reader(path).top(doc, "Models", MODEL_SCHEMA, "models"))


def models_json(models: MtModels) -> dict:
    return {"Models": _write(models.items, MODEL_SCHEMA)}


# ----------------------------------------------------------------------------- the .pbd side
def _section(pbd: Pbd, name: str, dtype: np.dtype) -> np.ndarray:
    k, off = pbd.counts[name], pbd.offsets[name]
    if k and (off < HEADER_SIZE or off + k * dtype.itemsize > len(pbd.raw)):
        raise FormatError(pbd.path, f"{k} {name.replace('_', ' ')} of {dtype.itemsize} bytes from offset {off} need "
                                    f"{off + k * dtype.itemsize} bytes, the file has {len(pbd.raw)}",
                          field=f"counts.{name}")
    return np.frombuffer(pbd.raw, dtype, count=k, offset=off if k else 0).copy()


def _instance_hashes(pbd: Pbd, k: int) -> np.ndarray:
    """Each instance's hash from the hash section's instance list (:meth:`Pbd.hash_list`), ``(k,)`` int64."""
    return pbd.hash_list("instances", k)


def _instance_items(rec: np.ndarray, hashes: np.ndarray, names: list[str] | None = None) -> list:
    """Instances.json objects of instance records ``(k,) INSTANCE_DTYPE`` (what a .pbd holds; the
    .ltg/.adl/.ssf fields at their defaults)."""
    loc, rot, scl = (_f32s(a).tolist() for a in decompose_rows(rec["matrix"]))
    lm = _f32s(rec["light_matrix"].transpose(0, 2, 1)).tolist()  # [i][j] = light vector j
    col = _f32s(rec["light_colour"]).tolist()
    vec_keys = ("LightVector1", "LightVector2", "LightVector3", "AmbentLightVector")
    col_keys = ("LightColour1", "LightColour2", "LightColour3", "AmbentLightColour")
    ints = {key: rec[f].tolist() for key, f in (("ModelID", "model_id"), ("PrevInstance", "prev"),
                                                 ("NextInstance", "next"))}
    ints.update({f"UnknownInt{n}": rec[f"unknown{n}"].tolist() for n in (26, 27, 28, 30, 31, 32)})
    hashes = np.asarray(hashes, np.int64).tolist()
    items = []
    for i in range(len(rec)):
        d = {"InstanceName": names[i] if names is not None else f"Instance_{i}",
             "Location": loc[i], "Rotation": rot[i], "Scale": scl[i]}
        for j, key in enumerate(vec_keys):
            d[key] = lm[i][j]
        for j, key in enumerate(col_keys):
            d[key] = col[i][j]
        for key, v in ints.items():
            d[key] = v[i]
        d["LTGState"] = 0
        d["Hash"] = hashes[i]
        items.append(_defaults(d, INSTANCE_SCHEMA))
    return items


def instances_from_placements(matrix: npt.ArrayLike, model: npt.ArrayLike, names: list[str] | None = None,
                              light_vectors: npt.ArrayLike | None = None, light_colours: npt.ArrayLike | None = None,
                              scale: float = GAME_SCALE) -> MtInstances:
    """piste's placed objects as Multitool instances: ``matrix (k, 4, 4)`` object -> world in
    piste's column form (metres; :meth:`MtInstances.placements` gives it back), ``model (k,)`` model
    indices, ``names`` (default ``Instance_<i>``), ``light_vectors`` / ``light_colours`` ``(k, 4,
    4)`` (rows: the three directional lights and the ambient one; default 0).  The matrix is
    decomposed into ``Location`` (game units) / ``Rotation`` / ``Scale``: a sheared matrix (piste's
    sloping rails) loses its shear, as the Multitool's L/R/S cannot hold one."""
    m = np.asarray(matrix, np.float64).reshape(-1, 4, 4)
    k = len(m)
    rows = m.transpose(0, 2, 1).copy()
    rows[:, 3, :3] /= scale
    rec = np.zeros(k, INSTANCE_DTYPE)
    rec["matrix"] = rows
    if light_vectors is not None:
        rec["light_matrix"] = np.asarray(light_vectors, np.float64).reshape(k, 4, 4).transpose(0, 2, 1)
    if light_colours is not None:
        rec["light_colour"] = np.asarray(light_colours, np.float64).reshape(k, 4, 4)
    rec["model_id"] = rec["model_id2"] = np.asarray(model, np.int64).reshape(k)
    rec["prev"] = rec["next"] = -1
    items = _instance_items(rec, np.zeros(k, np.int64), names)
    loc, rot, scl = (_f32s(a).tolist() for a in decompose_rows(rows))  # float64, not the record's float32
    for i, d in enumerate(items):
        d["Location"], d["Rotation"], d["Scale"] = loc[i], rot[i], scl[i]
    return MtInstances(items)


def _defaults(d: dict, schema: Any) -> dict:
    out = {}
    for key, kind, _ in schema:
        out[key] = d.get(key, 0 if kind in ("f", "i") else False if kind == "b" else None)
    return out


def instances_from_pbd(pbd: Pbd) -> MtInstances:
    """The level's instances as the Multitool exports them (module docstring)."""
    rec = _section(pbd, "instances", INSTANCE_DTYPE)
    return MtInstances(_instance_items(rec, _instance_hashes(pbd, len(rec))))


_PBD_INSTANCE_KEYS = ("Location", "Rotation", "Scale", "LightVector1", "LightVector2", "LightVector3",
                      "AmbentLightVector", "LightColour1", "LightColour2", "LightColour3", "AmbentLightColour",
                      "ModelID", "PrevInstance", "NextInstance", "UnknownInt26", "UnknownInt27", "UnknownInt28",
                      "UnknownInt30", "UnknownInt31", "UnknownInt32")


def _same(a: dict, b: dict, keys: Any) -> bool:
    if all(a[k] == b[k] for k in keys):  # the fast path (a NaN never compares equal)
        return True
    return json.dumps([_out_nested(a[k]) for k in keys]) == json.dumps([_out_nested(b[k]) for k in keys])


def _out_nested(v: Any) -> Any:
    if isinstance(v, list):
        return [_out_nested(x) for x in v]
    return _out_float(v) if isinstance(v, float) else v


def _instance_records(items: list, old: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):  # an old matrix of NaN / inf: its box is carried by translation
        return _instance_records_of(items, old)


def _instance_records_of(items: list, old: np.ndarray) -> np.ndarray:
    """Instance records of Instances.json objects, the Multitool's rebuild: the composed matrix,
    the light matrix's columns, colours, ids, ``model_id2`` = ``ModelID``; the bounds are the old
    record's box carried by the new placement (the Multitool computes them from the model's mesh,
    which piste does not decode)."""
    k = len(items)
    rec = old.copy()
    loc = np.array([d["Location"] for d in items], np.float64).reshape(k, 3)
    rot = np.array([d["Rotation"] for d in items], np.float64).reshape(k, 4)
    scl = np.array([d["Scale"] for d in items], np.float64).reshape(k, 3)
    new_m = compose_rows(loc, rot, scl)
    for j, key in enumerate(("LightVector1", "LightVector2", "LightVector3", "AmbentLightVector")):
        rec["light_matrix"][:, :, j] = [d[key] for d in items]
    for j, key in enumerate(("LightColour1", "LightColour2", "LightColour3", "AmbentLightColour")):
        rec["light_colour"][:, j] = [d[key] for d in items]
    for f, key in (("model_id", "ModelID"), ("prev", "PrevInstance"), ("next", "NextInstance"),
                   ("model_id2", "ModelID")):
        rec[f] = [d[key] for d in items]
    for n in (26, 27, 28, 30, 31, 32):
        rec[f"unknown{n}"] = [d[f"UnknownInt{n}"] for d in items]
    # the old box's corners, back through the old matrix into model space, out through the new one
    lo, hi = old["lowest"].astype(np.float64), old["highest"].astype(np.float64)
    bits = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], bool)
    corners = np.where(bits[None], hi[:, None], lo[:, None])  # (k, 8, 3)
    om = old["matrix"].astype(np.float64)
    ok = np.isfinite(om).reshape(k, -1).all(1) & (np.abs(np.linalg.det(np.where(np.isfinite(om), om, 0))) > 1e-12)
    inv = np.linalg.inv(np.where(ok[:, None, None], np.where(np.isfinite(om), om, 0), np.eye(4)))
    hom = np.concatenate([corners, np.ones((k, 8, 1))], 2)
    moved = hom @ inv @ new_m
    box_lo, box_hi = moved[..., :3].min(1), moved[..., :3].max(1)
    # an old matrix that cannot be inverted: the old box moved by the change of translation
    shift = new_m[:, 3, :3] - np.where(np.isfinite(om[:, 3, :3]), om[:, 3, :3], 0)
    rec["lowest"] = np.where(ok[:, None], box_lo, lo + shift)
    rec["highest"] = np.where(ok[:, None], box_hi, hi + shift)
    rec["matrix"] = new_m
    return rec


def instances_in_place(pbd: Pbd, data: bytearray, inst: MtInstances, path: str | os.PathLike[str] | None,
                       source_name: str) -> list:
    """Write ``inst`` over the level's instance records in ``data`` (the same count: the sections
    after them hold absolute offsets piste does not relocate); an instance whose ``.pbd`` fields did
    not change keeps its stored bytes; the hashes go into the hash section's instance list when it
    has one of that count.  Returns notes (what could not be kept)."""
    old = _section(pbd, "instances", INSTANCE_DTYPE)
    k = len(inst)
    if k != len(old):
        raise FormatError(path, f"{k} instances, but {source_name} holds {len(old)}: the count of a recorded level's "
                                "instances cannot change (the sections after them hold absolute offsets piste does not "
                                "relocate, and an instance's model lives in the level's model section)",
                          field="Instances")
    if k == 0:
        return []
    old_hash = _instance_hashes(pbd, k)
    was = _instance_items(old, old_hash)
    changed = np.array([not _same(a, b, _PBD_INSTANCE_KEYS) for a, b in zip(inst.items, was)], bool)
    n_models = pbd.counts["models"]
    for i in np.nonzero(changed)[0]:
        for key in ("Location", "Rotation", "Scale"):
            if not np.isfinite(inst.items[i][key]).all():
                raise FormatError(path, f"instance {i}: {key} must be finite numbers to place the instance, got "
                                        f"{inst.items[i][key]}", field=key)
        m = inst.items[i]["ModelID"]
        if not 0 <= m < n_models:
            raise FormatError(path, f"instance {i}: ModelID {m} is not one of the level's {n_models} models "
                                    f"(0..{n_models - 1})", field="ModelID")
    notes: list[str] = []
    if changed.any():
        new = _instance_records([inst.items[i] for i in np.nonzero(changed)[0]], old[changed])
        rec = old.copy()
        rec[changed] = new
        off = pbd.offsets["instances"]
        data[off:off + rec.nbytes] = rec.tobytes()
    want = inst.hash
    if np.array_equal(want, old_hash):
        return notes
    h = pbd.hash_header()
    if h is not None and h["count_instances"] == k:
        order = np.argsort(want, kind="stable")
        pairs = np.stack([want[order], order], 1).astype("<i4")
        lo = pbd.offsets["hash"] + h["offset_instances"]
        data[lo:lo + 8 * k] = pairs.tobytes()
    else:
        notes.append(f"{INSTANCES_JSON}: the instances' Hash values are not kept: {source_name} has no hash section "
                     f"with a list of {k} instance hashes to write them into")
    return notes


def _fit_coefficients(raw: np.ndarray) -> np.ndarray:
    """The Multitool's arc-length cubic of segments ``raw (s, 4, 3)`` game units: ``t`` against the
    polyline length in metres over :data:`FIT_SAMPLES` samples, least squares, highest power first,
    ``(s, 4)`` float64."""
    t = np.linspace(0.0, 1.0, FIT_SAMPLES)
    basis = np.stack([(1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2, t ** 3], 1)
    pts = np.einsum("tk,skc->stc", basis, raw)
    s = np.concatenate([np.zeros((len(raw), 1)), np.cumsum(np.linalg.norm(np.diff(pts, axis=1), axis=2), 1)], 1)
    s *= GAME_SCALE
    a = np.stack([s ** 3, s ** 2, s, np.ones_like(s)], 2)  # (segments, samples, 4)
    out = (np.linalg.pinv(a) @ t[:, None])[..., 0]  # every segment's least-squares solve at once
    return np.where((s[:, -1] > 0)[:, None], out, 0.0)  # a point segment: no fit (0, as the record's default)


def segment_records(raw: np.ndarray, spline: int, first: int) -> np.ndarray:
    """The Multitool's rebuilt segment records of one spline, ``raw (s, 4, 3)`` raw Bézier points
    (game units), its index ``spline`` and the index of its first segment ``first``: ``(s,)``
    :data:`SEGMENT_DTYPE`."""
    raw = np.asarray(raw, np.float64).reshape(-1, 4, 3)
    n = len(raw)
    rec = np.zeros(n, SEGMENT_DTYPE)
    power = np.einsum("pk,skc->spc", BEZIER_TO_POWER, raw)  # (s, 4 powers, 3)
    rec["power"][:, :, :3] = power[:, ::-1]
    rec["power"][:, 3, 3] = 1.0
    rec["coefficients"] = _fit_coefficients(raw)
    idx = first + np.arange(n)
    rec["prev"] = np.where(np.arange(n) == 0, -1, idx - 1)
    rec["next"] = np.where(np.arange(n) == n - 1, -1, idx + 1)
    rec["spline"] = spline
    rec["lowest"] = raw.min(1)
    rec["highest"] = raw.max(1)
    length = np.linalg.norm(np.diff(raw, axis=1), axis=2).sum(1)  # the control polygon (LineStrip.Distance)
    rec["length"] = length
    rec["length_before"] = np.concatenate([[0.0], np.cumsum(length)[:-1]])
    rec["unknown32"] = SEGMENT_UNKNOWN32
    return rec


def spline_sections(spl: MtSplines, path: str | os.PathLike[str] | None = None) -> dict:
    """The spline and segment sections of a new level (the Multitool's rebuild), as
    :func:`piste.formats.ssx.synth.pbd_bytes` takes them (FormatError naming ``path`` for
    non-finite points)."""
    splines = np.zeros(len(spl), SPLINE_DTYPE)
    segs = []
    first = 0
    for i in range(len(spl)):
        raw = spl.points(i)
        _finite_points(raw, path, i)
        seg = segment_records(raw, i, first)
        splines[i] = (raw.reshape(-1, 3).min(0), raw.reshape(-1, 3).max(0), 0, len(raw), first, -1)
        segs.append(seg)
        first += len(raw)
    seg = np.concatenate(segs) if segs else np.zeros(0, SEGMENT_DTYPE)
    return {"splines": (len(splines), splines.tobytes()), "spline_segments": (len(seg), seg.tobytes())}


def _raw_of(seg: np.ndarray) -> np.ndarray:
    """Raw Bézier points ``(s, 4, 3)`` float64 of segment records (the stored power basis)."""
    power = seg["power"][:, ::-1, :3].astype(np.float64)
    return np.einsum("kp,spc->skc", POWER_TO_BEZIER, power)


def _spline_parts(pbd: Pbd) -> tuple[np.ndarray, np.ndarray]:
    spl = _section(pbd, "splines", SPLINE_DTYPE)
    seg = _section(pbd, "spline_segments", SEGMENT_DTYPE)
    for i, s in enumerate(spl):
        a, n = int(s["segment_start"]), int(s["segment_count"])
        if a < 0 or n < 1 or a + n > len(seg):
            raise FormatError(pbd.path, f"spline {i}: segments {a}..{a + n - 1} are not within the level's "
                                        f"{len(seg)} segments", field="splines.segment_count")
    return spl, seg


def splines_from_pbd(pbd: Pbd) -> MtSplines:
    """The level's splines as the Multitool exports them: raw points of each segment's stored power
    basis, ``U0``/``U1``/``SplineStyle`` 0 (they live in the ``.ssf``), names ``Spline_<i>``."""
    spl, seg = _spline_parts(pbd)
    raw = _f32s(_raw_of(seg)).tolist()
    items = []
    for i, s in enumerate(spl):
        a, n = int(s["segment_start"]), int(s["segment_count"])
        segs = [{"Points": raw[j]} for j in range(a, a + n)]
        items.append({"SplineName": f"Spline_{i}", "U0": 0, "U1": 0, "SplineStyle": 0, "Segments": segs})
    return MtSplines(items)


def splines_in_place(pbd: Pbd, data: bytearray, spl: MtSplines, path: str | os.PathLike[str] | None,
                     source_name: str) -> None:
    """Write ``spl``'s points over the level's segments in ``data`` (the same splines with the same
    segment counts); a segment whose points did not change keeps its stored bytes, a changed one
    gets the Multitool's rebuilt record but keeps its stored links and ``Unknown32``; a spline
    with a changed segment gets its bounds and lengths-before recomputed."""
    old_spl, old_seg = _spline_parts(pbd)
    if len(spl) != len(old_spl):
        raise FormatError(path, f"{len(spl)} splines, but {source_name} holds {len(old_spl)}: the count of a recorded "
                                "level's splines cannot change (the sections after them hold absolute offsets piste "
                                "does not relocate)", field="Splines")
    was = splines_from_pbd(pbd)
    new_spl, new_seg = old_spl.copy(), old_seg.copy()
    for i, (s, w) in enumerate(zip(spl.items, was.items)):
        if len(s["Segments"]) != len(w["Segments"]):
            raise FormatError(path, f"spline {i}: {len(s['Segments'])} segments, but {source_name} holds "
                                    f"{len(w['Segments'])}: the segment count of a recorded level's spline cannot "
                                    "change", field="Segments")
        changed = [not _same(a, b, ("Points",)) for a, b in zip(s["Segments"], w["Segments"])]
        if not any(changed):
            continue
        a = int(old_spl[i]["segment_start"])
        raw = spl.points(i)
        _finite_points(raw, path, i, np.array(changed))
        built = segment_records(raw, i, a)
        for j, c in enumerate(changed):
            if c:
                keep = old_seg[a + j]
                built[j]["prev"], built[j]["next"] = keep["prev"], keep["next"]
                built[j]["spline"], built[j]["unknown32"] = keep["spline"], keep["unknown32"]
                new_seg[a + j] = built[j]
        run = new_seg[a:a + len(raw)]
        run["length_before"] = np.concatenate([[0.0], np.cumsum(run["length"].astype(np.float64))[:-1]])
        new_seg[a:a + len(raw)] = run
        new_spl[i]["lowest"] = run["lowest"].min(0)
        new_spl[i]["highest"] = run["highest"].max(0)
    for name, rec in (("splines", new_spl), ("spline_segments", new_seg)):
        off = pbd.offsets[name]
        if len(rec):
            data[off:off + rec.nbytes] = rec.tobytes()

