"""glTF extensions on import: which are read, which are refused, and the decoders.

:func:`piste.formats.gltf.read.load_gltf` calls :func:`check_required` once per file and
:func:`prepare_primitive` before it reads a primitive's attributes.

- ``extensionsRequired``: every entry must be in :data:`SUPPORTED` or the file is refused with a
  :class:`~piste.errors.FormatError` naming the extension (a required extension changes what the
  data means, so reading on would give garbage).  Extensions that are only *used* are optional by
  definition (the file carries fallback data) and are ignored when piste does not read them.
- **KHR_draco_mesh_compression**: the primitive's compressed bufferView is decoded with DracoPy (the
  optional ``gltf`` extra; without it a one-line error names the extra), the attributes are matched
  by their Draco unique ids and checked against the accessors' counts and component counts, and
  the decoded arrays stand in for those accessors (which have no bufferView).  A Draco buffer that
  does not decode, or decodes to the wrong counts, raises ``FormatError``: never zeros.
- **KHR_mesh_quantization**: integer ``POSITION`` / ``NORMAL`` / ``TEXCOORD_n`` / morph-target
  attributes (normalized or not) are accepted (the reader converts them to float; node transforms
  do the dequantization, as the extension specifies); quantized normals are re-normalised.
- **KHR_texture_transform**, **KHR_materials_emissive_strength**, **KHR_materials_unlit**: read into
  :class:`MaterialInfo` (:func:`material_info`), with base-colour factor and texture, alpha mode,
  alpha cutoff and double-sidedness.

API
---
SUPPORTED                                   names of the extensions piste reads
check_required(reader)                      refuse unsupported extensionsRequired
vertex_comps(reader, core)                  component types a vertex attribute may have
prepare_primitive(reader, prim, field)      decode KHR_draco_mesh_compression into the reader's cache
material_info(reader, index, field) -> MaterialInfo
texture_transform_matrix(offset, rotation, scale) -> (3, 3)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from piste.errors import FormatError
from piste.formats import safe_io
from piste.formats.gltf.material import MaterialInfo

# ``r`` below is the glTF reader of piste.formats.gltf.read (which imports this module) and the
# documents are JSON wrapped by Node_: both typed Any

__all__ = ["SUPPORTED", "check_required", "vertex_comps", "apply_uv_transform", "prepare_primitive", "MaterialInfo", "material_info",
           "texture_transform_matrix", "QUANTIZED_COMPS"]

SUPPORTED = (
    "KHR_draco_mesh_compression",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    "KHR_materials_emissive_strength",
    "KHR_materials_unlit",
    "KHR_lights_punctual",
)
#: component types allowed for vertex attributes with KHR_mesh_quantization (plus FLOAT)
QUANTIZED_COMPS = (5126, 5120, 5121, 5122, 5123)

_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_NORM_DIV = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0, 5125: 4294967295.0}


def to_float(raw: np.ndarray, component_type: int, normalized: bool) -> np.ndarray:
    """Accessor values as float64: normalized integers divided by their type's maximum (signed ones
    clamped at -1, as glTF specifies), everything else cast.  ``(n, c)`` in, ``(n, c) float64`` out."""
    if normalized and component_type != 5126:
        out = raw.astype(np.float64) / _NORM_DIV[component_type]
        return np.maximum(out, -1.0) if component_type in (5120, 5122) else out
    return raw.astype(np.float64)


def vertex_comps(r: Any, core: tuple[int, ...]) -> tuple[int, ...]:
    """Component types allowed for a vertex attribute: ``core`` (the glTF 2.0 core set), widened to
    :data:`QUANTIZED_COMPS` when the file declares KHR_mesh_quantization."""
    names = set(r.g.extensionsUsed or []) | set(r.g.extensionsRequired or [])
    return QUANTIZED_COMPS if "KHR_mesh_quantization" in names else core


def check_required(r: Any) -> None:
    """Raise FormatError for an ``extensionsRequired`` entry piste cannot read."""
    req = r.g.extensionsRequired or []
    if not isinstance(req, list):
        raise r.err("extensionsRequired", "expected a list of extension names")
    for k, name in enumerate(req):
        if name not in SUPPORTED:
            raise r.err(f"extensionsRequired[{k}]",
                        f"the file requires extension {name!r}, which piste cannot read "
                        f"(supported: {', '.join(SUPPORTED)})")


def _dracopy(r: Any) -> Any:
    try:
        import DracoPy
    except ImportError:
        raise FormatError(r.path, "KHR_draco_mesh_compression needs the 'gltf' extra: pip install 'piste[gltf]'",
                          field="extensions.KHR_draco_mesh_compression") from None
    return DracoPy


def prepare_primitive(r: Any, prim: Any, field: str) -> None:
    """Decode a KHR_draco_mesh_compression primitive into ``r``'s accessor cache (no-op otherwise)."""
    ext = prim.extensions if isinstance(prim.extensions, dict) else {}
    d = ext.get("KHR_draco_mesh_compression")
    if d is None:
        return
    efield = field + ".extensions.KHR_draco_mesh_compression"
    if not isinstance(d, dict) or not isinstance(d.get("attributes"), dict) or "bufferView" not in d:
        raise r.err(efield, "expected {bufferView, attributes}")
    draco = _dracopy(r)
    bv, data, off, ln = r.buffer_view(d["bufferView"], efield + ".bufferView")
    try:
        mesh = draco.decode(bytes(data[off:off + ln]))
    except Exception as e:  # DracoPy raises its own exception types (and ValueError) on corrupt data
        raise r.err(efield, f"cannot decode the Draco buffer ({type(e).__name__}: {e})") from None
    faces = getattr(mesh, "faces", None)
    if faces is None:
        raise r.err(efield, "the Draco buffer holds a point cloud, not a triangle mesh")
    attrs = prim.attributes
    for name, uid in d["attributes"].items():
        afield = f"{efield}.attributes.{name}"
        acc_i = getattr(attrs, name, None) if not name.startswith("_") else None
        if acc_i is None and isinstance(getattr(attrs, "__dict__", None), dict):
            acc_i = attrs.__dict__.get(name)
        if acc_i is None:
            raise r.err(afield, f"names attribute {name} which the primitive does not have")
        att = mesh.get_attribute_by_unique_id(uid) if isinstance(uid, int) else None
        if att is None:
            raise r.err(afield, f"no attribute with Draco unique id {uid!r} in the compressed buffer")
        _inject(r, acc_i, np.asarray(att["data"]), afield)
    if prim.indices is not None:
        _inject(r, prim.indices, np.asarray(faces, dtype=np.int64).reshape(-1, 1), efield + " (indices)")


def _inject(r: Any, acc_i: int, data: np.ndarray, field: str) -> None:
    a = r.item("accessors", acc_i, field)
    nc = _NCOMP.get(a.type)
    if nc is None or a.componentType not in _DTYPES:
        raise r.err(f"accessors[{acc_i}]", f"type {a.type}/{a.componentType} cannot hold Draco data")
    data = data.reshape(data.shape[0], -1)
    if data.shape != (a.count, nc):
        raise r.err(field, f"decodes to {data.shape[0]} x {data.shape[1]} values but accessors[{acc_i}] "
                           f"declares {a.count} x {nc}")
    raw = data.astype(_DTYPES[a.componentType])
    f = to_float(raw, a.componentType, a.normalized)
    if not np.all(np.isfinite(f)):
        raise r.err(field, "decoded values are not finite")
    r._accessors[(acc_i, False)] = f if a.normalized else raw
    r._accessors[(acc_i, True)] = f


# ---------------------------------------------------------------------------------------------
def texture_transform_matrix(offset: Sequence[float] | np.ndarray = (0.0, 0.0), rotation: float = 0.0,
                             scale: Sequence[float] | np.ndarray = (1.0, 1.0)) -> np.ndarray:
    """KHR_texture_transform's ``(3, 3)`` UV matrix ``T(offset) R(rotation) S(scale)`` (the
    extension's own definition: ``uv' = M @ (u, v, 1)``)."""
    c, s = np.cos(rotation), np.sin(rotation)
    t = np.array([[1, 0, offset[0]], [0, 1, offset[1]], [0, 0, 1]], dtype=np.float64)
    rm = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]], dtype=np.float64)
    sm = np.array([[scale[0], 0, 0], [0, scale[1], 0], [0, 0, 1]], dtype=np.float64)
    return t @ rm @ sm


def _finite(r: Any, v: Any, n: int, fld: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise r.err(fld, f"expected {n} finite numbers")
    return a


def material_info(r: Any, mi: int | None, field: str) -> MaterialInfo:
    """:class:`MaterialInfo` of ``materials[mi]`` (defaults when ``mi`` is None)."""
    if mi is None:
        return MaterialInfo()
    m = r.item("materials", mi, field)
    mf = f"materials[{mi}]"
    info = MaterialInfo(name=m.name or f"material{mi}")
    pbr = m.pbrMetallicRoughness
    if pbr is not None:
        if pbr.baseColorFactor is not None:
            info.base_color = _finite(r, pbr.baseColorFactor, 4, mf + ".pbrMetallicRoughness.baseColorFactor").astype(np.float32)
        bt = pbr.baseColorTexture
        if bt is not None and bt.index is not None:
            info.base_texture = int(bt.index)
            info.texcoord = int(bt.texCoord or 0)
            tex_ext = bt.extensions if isinstance(bt.extensions, dict) else {}
            tt = tex_ext.get("KHR_texture_transform")
            if isinstance(tt, dict):
                tf = mf + ".pbrMetallicRoughness.baseColorTexture.extensions.KHR_texture_transform"
                off = _finite(r, tt.get("offset", (0.0, 0.0)), 2, tf + ".offset")
                rot = float(_finite(r, [tt.get("rotation", 0.0)], 1, tf + ".rotation")[0])
                sc = _finite(r, tt.get("scale", (1.0, 1.0)), 2, tf + ".scale")
                info.uv_transform = texture_transform_matrix(off, rot, sc)
                if tt.get("texCoord") is not None:
                    info.texcoord = int(tt["texCoord"])
    mode = m.alphaMode or "OPAQUE"
    if mode not in ("OPAQUE", "MASK", "BLEND"):
        raise r.err(mf + ".alphaMode", f"is {mode!r}, expected OPAQUE, MASK or BLEND")
    info.alpha_mode = mode
    if m.alphaCutoff is not None:
        info.alpha_cutoff = float(_finite(r, [m.alphaCutoff], 1, mf + ".alphaCutoff")[0])
    info.double_sided = bool(m.doubleSided)
    ext = m.extensions if isinstance(m.extensions, dict) else {}
    em = np.zeros(3)
    if m.emissiveFactor is not None:
        em = _finite(r, m.emissiveFactor, 3, mf + ".emissiveFactor")
    es = ext.get("KHR_materials_emissive_strength")
    if isinstance(es, dict):
        em = em * float(_finite(r, [es.get("emissiveStrength", 1.0)], 1,
                                mf + ".extensions.KHR_materials_emissive_strength.emissiveStrength")[0])
    info.emissive = em.astype(np.float32)
    info.unlit = "KHR_materials_unlit" in ext
    return info


def apply_uv_transform(uv: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``(v, 2)`` UVs through a KHR_texture_transform matrix (identity: unchanged)."""
    if np.array_equal(m, np.eye(3)):
        return uv
    uv = np.asarray(uv, dtype=np.float64)
    return uv @ m[:2, :2].T + m[:2, 2]


# ---------------------------------------------------------------------------------------------
class Node_:
    """Attribute access to one JSON object of a glTF document, the way pygltflib exposes it
    (``prim.attributes.POSITION``, ``a.componentType``; a key that is absent reads as None).
    ``extensions`` and ``extras`` stay plain dicts; objects and lists of objects are wrapped on
    first access."""

    __slots__ = ("_d", "_c")

    def __init__(self, d: dict) -> None:
        object.__setattr__(self, "_d", d)
        object.__setattr__(self, "_c", {})

    def __getattr__(self, key: str) -> Any:
        if key.startswith("__"):
            raise AttributeError(key)
        c = self._c
        if key in c:
            return c[key]
        v = self._d.get(key)
        if key not in ("extensions", "extras"):
            v = _wrap(v)
        c[key] = v
        return v

    def __setattr__(self, key: str, value: Any) -> None:
        self._c[key] = value

    def get(self, key: str, default: Any = None) -> Any:
        """dict-style access (morph targets are read both ways)."""
        return getattr(self, key) if key in self._d else default

    def __repr__(self) -> str:
        return f"Node_({self._d!r})"


def _wrap(v: Any) -> Any:
    if isinstance(v, dict):
        return Node_(v)
    if isinstance(v, list) and v and any(isinstance(x, dict) for x in v):
        return [Node_(x) if isinstance(x, dict) else x for x in v]
    return v


class Document(Node_):
    """A parsed glTF document with pygltflib's reading API (``g.nodes``, ``g.binary_blob()``),
    made straight from the JSON that :func:`piste.formats.gltf.schema.precheck_gltf` already parsed:
    pygltflib's own ``GLTF2().load`` (dataclasses-json) took 70-95 % of ``load_gltf``'s time on the
    sample models (``benchmarks/bench_gltf.py``)."""

    __slots__ = ("_blob",)

    def __init__(self, doc: dict, blob: bytes | None) -> None:
        super().__init__(doc)
        object.__setattr__(self, "_blob", blob)

    def binary_blob(self) -> bytes | None:
        return self._blob


#: where a glTF document holds JSON objects (arrays of objects, and object-valued fields), checked
#: before attribute access so a number or string there is a FormatError naming it, not a traceback
_TOP_ARRAYS = ("accessors", "animations", "buffers", "bufferViews", "cameras", "images", "materials", "meshes",
               "nodes", "samplers", "scenes", "skins", "textures")
_NESTED = {
    "accessors": ("sparse", ("sparse", "indices"), ("sparse", "values")),
    "animations": ("[channels]", "[samplers]"),
    "meshes": ("[primitives]",),
    "materials": ("pbrMetallicRoughness", ("pbrMetallicRoughness", "baseColorTexture"),
                  ("pbrMetallicRoughness", "metallicRoughnessTexture"), "normalTexture", "occlusionTexture",
                  "emissiveTexture"),
    "cameras": ("perspective", "orthographic"),
}


def _check_shapes(path: str | os.PathLike[str], doc: dict[str, Any]) -> None:
    def need(v: Any, fld: str, kind: type = dict) -> None:
        if not isinstance(v, kind):
            what = "a JSON object" if kind is dict else "an array"
            raise FormatError(path, f"expected {what}, got {type(v).__name__} ({str(v)[:40]})", field=fld)

    for key in ("asset",) if "asset" in doc else ():
        need(doc[key], key)
    for key in _TOP_ARRAYS:
        if key not in doc:
            continue
        need(doc[key], key, list)
        for i, item in enumerate(doc[key]):
            need(item, f"{key}[{i}]")
            for sub in _NESTED.get(key, ()):
                if isinstance(sub, str) and sub.startswith("["):
                    name = sub[1:-1]
                    if name in item:
                        need(item[name], f"{key}[{i}].{name}", list)
                        for j, x in enumerate(item[name]):
                            need(x, f"{key}[{i}].{name}[{j}]")
                            if name == "primitives":
                                if "attributes" in x:
                                    need(x["attributes"], f"{key}[{i}].primitives[{j}].attributes")
                                for k, t in enumerate(x.get("targets") or []):
                                    need(t, f"{key}[{i}].primitives[{j}].targets[{k}]")
                            if name == "channels" and "target" in x:
                                need(x["target"], f"{key}[{i}].channels[{j}].target")
                    continue
                chain = (sub,) if isinstance(sub, str) else sub
                v = item
                for c in chain:
                    v = v.get(c) if isinstance(v, dict) else None
                if v is not None:
                    need(v, f"{key}[{i}]." + ".".join(chain))


def read_document(path: str | os.PathLike[str], doc: dict[str, Any]) -> Document:
    """A :class:`Document` of ``doc`` (the file's JSON) with the GLB binary chunk of ``path``, if any
    (the GLB framing was checked by ``precheck_gltf``)."""
    import struct

    _check_shapes(path, doc)
    blob = None
    with safe_io.open_file(path, safe_io.MAX_MODEL_BYTES, what="model file") as f:  # the file precheck_gltf read
        head = f.read(20)
        if head[:4] == b"glTF" and len(head) == 20:
            _, _, length = struct.unpack_from("<4sII", head, 0)
            clen = struct.unpack_from("<I", head, 12)[0]
            f.seek(20 + clen)
            ch = f.read(8)
            if len(ch) == 8:
                blen, btype = struct.unpack("<II", ch)
                if btype == 0x004E4942:
                    blob = f.read(min(blen, max(length - 28 - clen, 0)))
    return Document(doc, blob)
