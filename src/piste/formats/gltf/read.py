"""glTF 2.0 import (``.gltf`` + ``.bin`` / data URIs, and ``.glb``) into :class:`piste.character.Model`.

The JSON / GLB container is parsed by :func:`piste.formats.gltf.schema.precheck_gltf` and read through
:class:`piste.formats.gltf.extensions.Document` (pygltflib's attribute API, without its slow parse); this
module turns it into numpy data and
validates everything it reads (errors raise :class:`piste.errors.FormatError` naming the file and
the glTF field, e.g. ``accessors[3]``).

What is imported
----------------
- **Meshes**: one :class:`SkinnedMesh` per primitive (primitives are *not* merged: each may carry
  its own material/texture). Name: the glTF mesh name (``mesh<i>`` when unnamed), with ``/<p>``
  appended when the mesh has several primitives, prefixed ``<node>:`` when a mesh is instanced
  by several nodes. TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN are read (strips/fans become
  triangle lists); POINTS/LINES primitives are skipped. Missing normals are computed.
- **Skeleton**: the joints of every skin, plus their ancestors, plus nodes animated by TRS
  channels and unskinned mesh nodes (and their ancestors), ordered parents-first. Non-joint bones
  get ``inverse_bind = inverse(rest world)``, so an unskinned mesh attached to a node is stored in
  world space at rest with weight 1 on its node's bone and moves rigidly with it. If two skins
  give one joint different inverse bind matrices, a child bone ``name#skin<i>`` with identity
  local transform carries the second one. A model with no skin and no TRS animation has
  ``skeleton=None`` and its meshes are baked into world space (``skinned=False``).
- **Skinned meshes** keep their bind-space positions (the mesh node's own transform is ignored,
  as the glTF spec says); JOINTS_n/WEIGHTS_n sets beyond the first are merged keeping the 4
  largest weights; rows are renormalised to sum to 1.
- **Animations**: translation, rotation, scale and weights channels; LINEAR, STEP, CUBICSPLINE;
  normalized integer outputs; clips keyed by name (``animation<i>`` when unnamed).
- **Morph targets**: POSITION and NORMAL deltas, names from ``extras.targetNames``, default
  weights from the node or mesh ``weights``.
- **Materials**: base-colour factor and base-colour texture (decoded with Pillow to RGBA uint8).
- **Lights** (KHR_lights_punctual) and **cameras** placed with their nodes' rest world transforms, as
  piste's own (:mod:`piste.scene_data`: Z up, relative light units) by the conventions of
  :mod:`piste.formats.gltf.units` in the ``frame`` given (default: glTF's Y up, 1 m, 683 lux white).
- Accessors: any byte stride, normalized integers, sparse accessors.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from piste.character.model import Clip, Model, Skeleton, SkinnedMesh, Track
from piste.character.skeleton import topological_order, world_from_local
from piste.errors import FormatError, ValidationError
from piste.formats import safe_io
from piste.formats.gltf.units import GltfFrame, camera_from_gltf, light_from_gltf
from piste.formats.gltf import checks as gltf_checks
from piste.formats.gltf import extensions as gltf_ext
from piste.formats.gltf.schema import precheck_gltf
from piste.transforms import compose_trs, decompose_trs, transform_points, transform_vectors

__all__ = ["load_gltf"]

_COMP = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_FLOAT = 5126


class _Reader:
    """Validated access to one glTF document's buffers, accessors and images."""

    def __init__(self, path: Path, g: Any, allow_paths: Iterable[str | os.PathLike[str]] = ()) -> None:
        self.path = path
        self.g = g
        self.allow_paths = tuple(allow_paths)  # folders besides the model's own that URIs may name
        self._buffers: dict[int, bytes] = {}
        self._accessors: dict[tuple[int, bool], np.ndarray] = {}

    def err(self, field: str, message: str) -> FormatError:
        return FormatError(self.path, message, field=field)

    # ------------------------------------------------------------------ lists
    def item(self, kind: str, index: Any, field: str) -> Any:
        lst = getattr(self.g, kind) or []
        if not isinstance(index, (int, np.integer)) or isinstance(index, bool) or not 0 <= index < len(lst):
            raise self.err(field, f"refers to {kind}[{index}] but the file has {len(lst)} {kind}")
        return lst[index]

    # ------------------------------------------------------------------ buffers
    def buffer(self, i: int) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        b = self.item("buffers", i, f"buffers[{i}]")
        field = f"buffers[{i}]"
        if b.uri is None:
            data = None
            if i == 0:
                try:
                    data = self.g.binary_blob()
                except Exception:  # pragma: no cover - pygltflib internals
                    data = None
            if data is None:
                raise self.err(field, "has no uri and the file has no GLB binary chunk")
        elif not isinstance(b.uri, str):
            raise self.err(field + ".uri", f"expected a string, got {b.uri!r}")
        elif b.uri.startswith("data:"):
            data = safe_io.decode_data_uri(b.uri, self._byte_cap(b.byteLength, field), self.path, field + ".uri")
        else:  # confined to the model's folder (or allow_paths), regular files only, byteLength bytes
            f = safe_io.resolve_reference(self.path, b.uri, self.allow_paths, field + ".uri")
            data = safe_io.read_regular(f, safe_io.MAX_BUFFER_BYTES, self.path, field + ".uri",
                                        length=self._byte_cap(b.byteLength, field), what="buffer file",
                                        length_field=field + ".byteLength")
        data = bytes(data)
        if b.byteLength is None or len(data) < b.byteLength:
            raise self.err(field + ".byteLength", f"declares {b.byteLength} bytes but only {len(data)} are present")
        self._buffers[i] = data
        return data

    def _byte_cap(self, n: Any, field: str) -> int:
        """A buffer's declared ``byteLength``, checked to be an integer within the cap before reading."""
        if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= safe_io.MAX_BUFFER_BYTES:
            raise self.err(field + ".byteLength", f"expected a byte count in 0..{safe_io.MAX_BUFFER_BYTES}, got {n!r}")
        return n

    def buffer_view(self, i: int, field: str) -> tuple[Any, bytes, int, int]:
        bv = self.item("bufferViews", i, field)
        bfield = f"bufferViews[{i}]"
        data = self.buffer(bv.buffer) if isinstance(bv.buffer, int) else None
        if data is None:
            raise self.err(bfield + ".buffer", f"bad buffer index {bv.buffer!r}")
        off = bv.byteOffset or 0
        ln = bv.byteLength
        if ln is None or off < 0 or ln < 0 or off + ln > len(data):
            raise self.err(bfield, f"byte range [{off}, {off}+{ln}) lies outside buffers[{bv.buffer}] ({len(data)} bytes)")
        return bv, data, off, ln

    # ------------------------------------------------------------------ accessors
    def accessor(self, i: Any, field: str, types: tuple[str, ...] | None = None, comps: tuple[int, ...] | None = None,
                 floatify: bool = True) -> np.ndarray:
        """Accessor ``i`` as ``(count, ncomp)`` array (float64 when ``floatify`` or normalized).

        ``types``: allowed accessor types; ``comps``: allowed component types (5126 float, ...).
        """
        a = self.item("accessors", i, field)
        afield = f"{field} (accessors[{i}])" if not field.startswith("accessors") else field
        if a.type not in _NCOMP:
            raise self.err(afield + ".type", f"unknown accessor type {a.type!r}")
        if a.componentType not in _COMP:
            raise self.err(afield + ".componentType", f"unknown component type {a.componentType!r}")
        if types is not None and a.type not in types:
            raise self.err(afield + ".type", f"is {a.type}, expected {' or '.join(types)}")
        if comps is not None and a.componentType not in comps:
            names = {5120: "BYTE", 5121: "UNSIGNED_BYTE", 5122: "SHORT", 5123: "UNSIGNED_SHORT",
                     5125: "UNSIGNED_INT", 5126: "FLOAT"}
            raise self.err(afield + ".componentType",
                           f"is {names[a.componentType]}, expected {' or '.join(names[c] for c in comps)}")
        key = (i, floatify)
        if key in self._accessors:
            return self._accessors[key]
        dt = np.dtype(_COMP[a.componentType]).newbyteorder("<")
        nc = _NCOMP[a.type]
        count = a.count
        if not isinstance(count, int) or count < 0:
            raise self.err(afield + ".count", f"bad count {count!r}")
        if a.bufferView is None:
            arr = np.zeros((count, nc), dtype=dt)
        else:
            bv, data, off, ln = self.buffer_view(a.bufferView, afield + ".bufferView")
            elem = dt.itemsize * nc
            stride = bv.byteStride or elem
            aoff = a.byteOffset or 0
            if stride < elem:
                raise self.err(f"bufferViews[{a.bufferView}].byteStride", f"{stride} is smaller than the element size {elem}")
            need = aoff + (stride * (count - 1) + elem if count else 0)
            if aoff < 0 or need > ln:
                raise self.err(afield, f"reads {need} bytes from bufferViews[{a.bufferView}] which has {ln} "
                                       f"(count {count}, offset {aoff}, stride {stride})")
            if count:
                arr = np.ndarray((count, nc), dtype=dt, buffer=data, offset=off + aoff,
                                 strides=(stride, dt.itemsize)).copy()
            else:
                arr = np.zeros((0, nc), dtype=dt)
        if a.sparse is not None:
            arr = self._apply_sparse(a, arr, afield)
        if floatify or a.normalized:
            out = gltf_ext.to_float(arr, a.componentType, a.normalized)
            if not np.all(np.isfinite(out)):
                bad = int(np.flatnonzero(~np.all(np.isfinite(out), axis=1))[0])
                raise self.err(afield, f"element {bad} is not finite (NaN or infinity)")
            arr = out
        self._accessors[key] = arr
        return arr

    def _apply_sparse(self, a: Any, arr: np.ndarray, afield: str) -> np.ndarray:
        sp = a.sparse
        n = sp.count
        sfield = afield + ".sparse"
        if not isinstance(n, int) or n < 1 or n > a.count:
            raise self.err(sfield + ".count", f"bad sparse count {n!r} for an accessor of {a.count} elements")
        idx_t = sp.indices.componentType
        if idx_t not in (5121, 5123, 5125):
            raise self.err(sfield + ".indices.componentType", f"is {idx_t!r}, expected an unsigned integer type")
        idt = np.dtype(_COMP[idx_t]).newbyteorder("<")
        bv, data, off, ln = self.buffer_view(sp.indices.bufferView, sfield + ".indices.bufferView")
        ioff = sp.indices.byteOffset or 0
        if ioff + n * idt.itemsize > ln:
            raise self.err(sfield + ".indices", "reads past the end of its bufferView")
        idx = np.frombuffer(data, dtype=idt, count=n, offset=off + ioff).astype(np.int64)
        if np.any(idx >= a.count):
            raise self.err(sfield + ".indices", f"index {int(idx.max())} out of range for {a.count} elements")
        dt = arr.dtype
        nc = arr.shape[1]
        bv, data, off, ln = self.buffer_view(sp.values.bufferView, sfield + ".values.bufferView")
        voff = sp.values.byteOffset or 0
        if voff + n * nc * dt.itemsize > ln:
            raise self.err(sfield + ".values", "reads past the end of its bufferView")
        vals = np.frombuffer(data, dtype=dt, count=n * nc, offset=off + voff).reshape(n, nc)
        arr = arr.copy()
        arr[idx] = vals
        return arr

    # ------------------------------------------------------------------ images
    def image(self, i: int, field: str) -> np.ndarray:
        from PIL import Image

        img = self.item("images", i, field)
        ifield = f"images[{i}]"
        if img.uri is not None:
            if not isinstance(img.uri, str):
                raise self.err(ifield + ".uri", f"expected a string, got {img.uri!r}")
            if img.uri.startswith("data:"):
                data = safe_io.decode_data_uri(img.uri, safe_io.MAX_IMAGE_BYTES, self.path, ifield + ".uri")
            else:  # confined to the model's folder (or allow_paths), regular files only, size-capped
                f = safe_io.resolve_reference(self.path, img.uri, self.allow_paths, ifield + ".uri")
                data = safe_io.read_regular(f, safe_io.MAX_IMAGE_BYTES, self.path, ifield + ".uri", what="image file")
        elif img.bufferView is not None:
            bv, buf, off, ln = self.buffer_view(img.bufferView, ifield + ".bufferView")
            data = buf[off:off + ln]
        else:
            raise self.err(ifield, "has neither uri nor bufferView")
        try:
            with Image.open(io.BytesIO(data)) as im:
                if im.width * im.height > safe_io.MAX_IMAGE_PIXELS:  # header only: checked before decoding
                    raise ValueError(f"{im.width} x {im.height} pixels, more than the limit of "
                                     f"{safe_io.MAX_IMAGE_PIXELS}")
                return np.asarray(im.convert("RGBA"), dtype=np.uint8).copy()
        except Exception as e:
            raise self.err(ifield, f"cannot decode image: {e}") from None


# ---------------------------------------------------------------------------------------------
def _node_local(r: _Reader, i: int, n: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    field = f"nodes[{i}]"
    if n.matrix is not None:
        m = np.asarray(n.matrix, dtype=np.float64)
        if m.shape != (16,) or not np.all(np.isfinite(m)):
            raise r.err(field + ".matrix", "expected 16 finite numbers")
        t, q, s = decompose_trs(m.reshape(4, 4).T)  # glTF stores column-major
        return t, q, s
    vals = []
    for name, default, size in (("translation", (0.0, 0.0, 0.0), 3), ("rotation", (0.0, 0.0, 0.0, 1.0), 4),
                                ("scale", (1.0, 1.0, 1.0), 3)):
        v = getattr(n, name)
        v = np.asarray(default if v is None else v, dtype=np.float64)
        if v.shape != (size,) or not np.all(np.isfinite(v)):
            raise r.err(f"{field}.{name}", f"expected {size} finite numbers")
        vals.append(v)
    t, q, s = vals
    nq = np.linalg.norm(q)
    if nq < 1e-8:
        raise r.err(field + ".rotation", "quaternion has zero length")
    return t, q / nq, s


def _unique(names: Iterable[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for n in names:
        if n in seen:
            seen[n] += 1
            m = f"{n}#{seen[n]}"
            while m in seen:
                seen[n] += 1
                m = f"{n}#{seen[n]}"
            seen[m] = 0
            out.append(m)
        else:
            seen[n] = 0
            out.append(n)
    return out


def _triangles(r: _Reader, prim: Any, nv: int, field: str) -> np.ndarray | None:
    mode = 4 if prim.mode is None else prim.mode
    if mode not in (4, 5, 6):
        return None
    if prim.indices is not None:
        idx = r.accessor(prim.indices, field + ".indices", types=("SCALAR",), comps=(5121, 5123, 5125),
                         floatify=False).reshape(-1).astype(np.int64)
    else:
        idx = np.arange(nv, dtype=np.int64)
    if idx.size and (idx.max() >= nv):
        raise r.err(field + ".indices", f"vertex index {int(idx.max())} out of range for {nv} vertices")
    if mode == 4:
        if idx.size % 3:
            raise r.err(field + ".indices", f"{idx.size} indices is not a multiple of 3 for TRIANGLES")
        tri = idx.reshape(-1, 3)
    elif mode == 5:
        k = np.arange(max(idx.size - 2, 0))
        even = (k % 2) == 0
        a = idx[k]
        b = np.where(even, idx[k + 1], idx[k + 2])
        c = np.where(even, idx[k + 2], idx[k + 1])
        tri = np.stack([a, b, c], axis=1)
    else:
        k = np.arange(1, max(idx.size - 1, 1))
        tri = np.stack([np.full(k.size, idx[0] if idx.size else 0), idx[k], idx[k + 1]], axis=1) if idx.size >= 3 \
            else np.zeros((0, 3), np.int64)
    keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2]) if mode != 4 else slice(None)
    return tri[keep].astype(np.uint32)


def _skin_attributes(r: _Reader, attrs: Any, nv: int, n_joints: int,
                     field: str) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """JOINTS_n / WEIGHTS_n merged to ``(v, 4) int64`` joints (skin-local) and ``(v, 4)`` weights."""
    js, ws = [], []
    k = 0
    while True:
        ja = getattr(attrs, f"JOINTS_{k}", None)
        wa = getattr(attrs, f"WEIGHTS_{k}", None)
        if ja is None and wa is None:
            break
        if ja is None or wa is None:
            raise r.err(f"{field}.attributes", f"JOINTS_{k} and WEIGHTS_{k} must come together")
        j = r.accessor(ja, f"{field}.attributes.JOINTS_{k}", types=("VEC4",), comps=(5121, 5123), floatify=False)
        w = r.accessor(wa, f"{field}.attributes.WEIGHTS_{k}", types=("VEC4",), comps=(5126, 5121, 5123))
        if j.shape[0] != nv or w.shape[0] != nv:
            raise r.err(f"{field}.attributes.JOINTS_{k}", f"count differs from POSITION's {nv}")
        j = j.astype(np.int64)
        if np.any(w < 0):
            raise r.err(f"{field}.attributes.WEIGHTS_{k}", "negative weight")
        bad = (w > 0) & (j >= n_joints)
        if np.any(bad):
            raise r.err(f"{field}.attributes.JOINTS_{k}",
                        f"joint index {int(j[bad].max())} out of range for a skin of {n_joints} joints")
        js.append(np.where(j >= n_joints, 0, j))
        ws.append(w)
        k += 1
    if not js:
        return None, None
    j = np.concatenate(js, axis=1)
    w = np.concatenate(ws, axis=1)
    if j.shape[1] > 4:
        order = np.argsort(-w, axis=1, kind="stable")[:, :4]
        j = np.take_along_axis(j, order, axis=1)
        w = np.take_along_axis(w, order, axis=1)
    s = w.sum(axis=1, keepdims=True)
    zero = s[:, 0] <= 0
    w = np.where(zero[:, None], np.array([1.0, 0.0, 0.0, 0.0]), w / np.where(s > 0, s, 1.0))
    j = np.where(w > 0, j, 0)
    return j, w


def load_gltf(path: str | os.PathLike[str], allow_paths: Iterable[str | os.PathLike[str]] = (), frame: GltfFrame | None = None) -> Model:
    """Load a glTF 2.0 file (``.gltf`` with external/embedded buffers, or ``.glb``) as a Model.

    Buffer and image URIs are read only inside the model's folder, or inside one of the folders
    ``allow_paths`` names (see :mod:`piste.formats.safe_io`); sizes and counts are capped
    (:mod:`piste.formats.limits`) before anything is allocated.  ``frame``
    (:class:`piste.formats.gltf.units.GltfFrame`) places the file's lights and cameras in piste's
    world (``Model.lights``, ``Model.cameras``: :mod:`piste.scene_data` objects); the meshes keep
    the file's axes.  Raises FormatError naming the file and the glTF field on malformed input.
    See the module docstring for what is imported and how.
    """
    path = Path(path)
    frame = GltfFrame() if frame is None else frame
    if not path.exists() and not path.is_symlink():
        raise FormatError(path, "no such file")
    doc = precheck_gltf(path)  # read through safe_io: a pipe, device, folder or link refused by name  # file size, GLB chunks, JSON nesting and array counts
    g = gltf_ext.read_document(path, doc)  # pygltflib's reading API over that JSON (its own parse was 70-95 % of the time)
    r = _Reader(path, g, allow_paths)
    gltf_ext.check_required(r)  # every extensionsRequired entry is read or refused by name
    nodes = g.nodes or []
    nn = len(nodes)

    # ---------------------------------------------------------------- node hierarchy
    parent = np.full(nn, -1, dtype=np.int64)
    for i, n in enumerate(nodes):
        for c in n.children or []:
            if not isinstance(c, int) or not 0 <= c < nn:
                raise r.err(f"nodes[{i}].children", f"child {c!r} is not a node index (0..{nn - 1})")
            if parent[c] >= 0 or c == i:
                raise r.err(f"nodes[{i}].children", f"node {c} has more than one parent")
            parent[c] = i
    try:
        order = topological_order(parent)
    except Exception:
        raise r.err("nodes", "node hierarchy has a cycle") from None
    local_t = np.zeros((nn, 3))
    local_r = np.zeros((nn, 4))
    local_s = np.ones((nn, 3))
    for i, n in enumerate(nodes):
        local_t[i], local_r[i], local_s[i] = _node_local(r, i, n)
    # world rest matrices of all nodes (computed in topological order)
    inv_order = np.empty(nn, dtype=np.int64)
    inv_order[order] = np.arange(nn)
    par_o = np.where(parent[order] >= 0, inv_order[np.maximum(parent[order], 0)], -1)
    world_o = world_from_local(compose_trs(local_t[order], local_r[order], local_s[order]), par_o)
    node_world = np.empty_like(world_o)
    node_world[order] = world_o

    # scene membership
    if g.scenes:
        si = g.scene if g.scene is not None else 0
        scene = r.item("scenes", si, "scene")
        roots = list(scene.nodes or [])
        for k, ri in enumerate(roots):
            r.item("nodes", ri, f"scenes[{si}].nodes[{k}]")
    else:
        roots = [i for i in range(nn) if parent[i] < 0]
    in_scene = np.zeros(nn, bool)
    in_scene[roots] = True
    for i in order:  # parents first
        if parent[i] >= 0 and in_scene[parent[i]]:
            in_scene[i] = True
    node_names = _unique([n.name if n.name else f"node{i}" for i, n in enumerate(nodes)])

    # ---------------------------------------------------------------- skins
    skins = g.skins or []
    skin_ibm = []
    for si, s in enumerate(skins):
        sj = list(s.joints or [])
        if not sj:
            raise r.err(f"skins[{si}].joints", "is empty")
        for k, j in enumerate(sj):
            r.item("nodes", j, f"skins[{si}].joints[{k}]")
        if s.inverseBindMatrices is not None:
            ibm = r.accessor(s.inverseBindMatrices, f"skins[{si}].inverseBindMatrices", types=("MAT4",), comps=(_FLOAT,))
            if ibm.shape[0] < len(sj):
                raise r.err(f"skins[{si}].inverseBindMatrices",
                            f"has {ibm.shape[0]} matrices for {len(sj)} joints")
            ibm = ibm[: len(sj)].reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major -> row-major
        else:
            ibm = np.tile(np.eye(4), (len(sj), 1, 1))
        skin_ibm.append(ibm)

    # ---------------------------------------------------------------- which nodes are bones
    animations = g.animations or []
    trs_animated = set()
    for ai, a in enumerate(animations):
        for ci, ch in enumerate(a.channels or []):
            tgt = ch.target
            if tgt is None or tgt.path not in ("translation", "rotation", "scale", "weights"):
                continue  # unknown paths (e.g. KHR_animation_pointer) are ignored
            if tgt.node is None:
                continue
            r.item("nodes", tgt.node, f"animations[{ai}].channels[{ci}].target.node")
            if tgt.path != "weights":
                trs_animated.add(tgt.node)
    joint_nodes = {j for s in skins for j in s.joints}
    mesh_nodes = [i for i in range(nn) if nodes[i].mesh is not None and in_scene[i]]
    has_skeleton = bool(joint_nodes) or bool(trs_animated)
    bone_nodes: list[int] = []
    if has_skeleton:
        want = np.zeros(nn, bool)
        for j in joint_nodes | trs_animated:
            want[j] = True
        for i in mesh_nodes:
            if nodes[i].skin is None:
                want[i] = True
        for i in order[::-1]:  # children first: mark ancestors
            if want[i] and parent[i] >= 0:
                want[parent[i]] = True
        bone_nodes = [int(i) for i in order if want[i]]

    # ---------------------------------------------------------------- skeleton
    skeleton = None
    bone_of_node: dict[int, int] = {}
    skin_bones: list[np.ndarray] = []
    if has_skeleton:
        b_nodes = list(bone_nodes)
        ibm_all = [gltf_checks.rest_inverse(node_world[i]) for i in b_nodes]  # identity if scaled to 0
        is_joint = [False] * len(b_nodes)
        idx_of: dict[int | tuple[int, int], int] = {n: k for k, n in enumerate(b_nodes)}
        names = [node_names[i] for i in b_nodes]
        par = [idx_of.get(int(parent[i]), -1) if parent[i] >= 0 else -1 for i in b_nodes]
        rt = [local_t[i] for i in b_nodes]
        rr = [local_r[i] for i in b_nodes]
        rs = [local_s[i] for i in b_nodes]
        nidx = list(b_nodes)
        for si, s in enumerate(skins):
            sb = []
            for k, j in enumerate(s.joints):
                bi = idx_of[j]
                if not is_joint[bi]:
                    is_joint[bi] = True
                    ibm_all[bi] = skin_ibm[si][k]
                elif not np.allclose(ibm_all[bi], skin_ibm[si][k], atol=1e-6, rtol=1e-5):
                    # same joint, different bind: a child bone with identity local transform
                    key = (j, si)
                    if key not in idx_of:
                        idx_of[key] = len(names)
                        names.append(f"{node_names[j]}#skin{si}")
                        par.append(bi)
                        rt.append(np.zeros(3))
                        rr.append(np.array([0.0, 0.0, 0.0, 1.0]))
                        rs.append(np.ones(3))
                        ibm_all.append(skin_ibm[si][k])
                        is_joint.append(True)
                        nidx.append(-1)
                    bi = idx_of[key]
                sb.append(bi)
            skin_bones.append(np.asarray(sb, dtype=np.int64))
        skeleton, sk_order = Skeleton.ordered(_unique(names), par, np.array(rt), np.array(rr), np.array(rs),
                                              np.array(ibm_all), node_index=np.array(nidx), is_joint=np.array(is_joint))
        new_of_old = np.empty(len(sk_order), np.int64)
        new_of_old[sk_order] = np.arange(len(sk_order))
        skin_bones = [new_of_old[sb] for sb in skin_bones]
        for k, n in enumerate(b_nodes):
            bone_of_node[n] = int(new_of_old[k])

    # ---------------------------------------------------------------- materials / textures
    image_cache: dict[int, np.ndarray] = {}

    def material(mi: Any, field: str) -> tuple[np.ndarray | None, np.ndarray]:
        if mi is None:
            return None, np.ones(4, np.float32)
        m = r.item("materials", mi, field)
        pbr = m.pbrMetallicRoughness
        color = np.ones(4, np.float32)
        tex = None
        if pbr is not None:
            if pbr.baseColorFactor is not None:
                color = np.asarray(pbr.baseColorFactor, dtype=np.float32).reshape(-1)
                if color.shape != (4,) or not np.all(np.isfinite(color)):
                    raise r.err(f"materials[{mi}].pbrMetallicRoughness.baseColorFactor", "expected 4 finite numbers")
            if pbr.baseColorTexture is not None and pbr.baseColorTexture.index is not None:
                ti = pbr.baseColorTexture.index
                t = r.item("textures", ti, f"materials[{mi}].pbrMetallicRoughness.baseColorTexture.index")
                if t.source is not None:
                    if t.source not in image_cache:
                        image_cache[t.source] = r.image(t.source, f"textures[{ti}].source")
                    tex = image_cache[t.source]
        return tex, color

    # ---------------------------------------------------------------- meshes
    mesh_list = g.meshes or []
    group_names = _unique([m.name if m.name else f"mesh{i}" for i, m in enumerate(mesh_list)])
    uses: dict[int, int] = {}
    for i in mesh_nodes:
        uses[nodes[i].mesh] = uses.get(nodes[i].mesh, 0) + 1
    meshes = []
    for ni in mesh_nodes:
        node = nodes[ni]
        mi = node.mesh
        mesh = r.item("meshes", mi, f"nodes[{ni}].mesh")
        group = group_names[mi]
        prims = mesh.primitives or []
        skin_i = node.skin
        if skin_i is not None:
            r.item("skins", skin_i, f"nodes[{ni}].skin")
        extras = mesh.extras if isinstance(mesh.extras, dict) else {}
        tnames = extras.get("targetNames") or []
        # node.weights, else mesh.weights; both optional (pygltflib gives [] when absent): 0 then
        default_w = getattr(node, "weights", None) or mesh.weights or None
        for pi, prim in enumerate(prims):
            field = f"meshes[{mi}].primitives[{pi}]"
            attrs = prim.attributes
            if attrs is None or attrs.POSITION is None:
                raise r.err(field + ".attributes.POSITION", "is missing")
            gltf_ext.prepare_primitive(r, prim, field)  # KHR_draco_mesh_compression
            pos = r.accessor(attrs.POSITION, field + ".attributes.POSITION", types=("VEC3",), comps=gltf_ext.vertex_comps(r, (_FLOAT,)))
            nv = pos.shape[0]
            tri = _triangles(r, prim, nv, field)
            if tri is None:
                continue
            nrm = None
            if attrs.NORMAL is not None:
                nrm = r.accessor(attrs.NORMAL, field + ".attributes.NORMAL", types=("VEC3",), comps=gltf_ext.vertex_comps(r, (_FLOAT,)))
                nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)  # quantized normals
                if nrm.shape[0] != nv:
                    raise r.err(field + ".attributes.NORMAL", f"count {nrm.shape[0]} differs from POSITION's {nv}")
            uv = None
            if attrs.TEXCOORD_0 is not None:
                uv = r.accessor(attrs.TEXCOORD_0, field + ".attributes.TEXCOORD_0", types=("VEC2",),
                                comps=gltf_ext.vertex_comps(r, (_FLOAT, 5121, 5123)))
                if uv.shape[0] != nv:
                    raise r.err(field + ".attributes.TEXCOORD_0", f"count {uv.shape[0]} differs from POSITION's {nv}")
            # morph targets
            targets = prim.targets or []
            k = len(targets)
            mpos = np.zeros((k, nv, 3))
            mnrm = np.zeros((k, nv, 3))
            for ti, tgt in enumerate(targets):
                tget = tgt.get if isinstance(tgt, dict) else (lambda a, t=tgt: getattr(t, a, None))
                tf = f"{field}.targets[{ti}]"
                if tget("POSITION") is not None:
                    d = r.accessor(tget("POSITION"), tf + ".POSITION", types=("VEC3",), comps=(_FLOAT, 5120, 5122))
                    if d.shape[0] != nv:
                        raise r.err(tf + ".POSITION", f"count {d.shape[0]} differs from the primitive's {nv} vertices")
                    mpos[ti] = d
                if tget("NORMAL") is not None:
                    d = r.accessor(tget("NORMAL"), tf + ".NORMAL", types=("VEC3",), comps=(_FLOAT, 5120, 5122))
                    if d.shape[0] != nv:
                        raise r.err(tf + ".NORMAL", f"count {d.shape[0]} differs from the primitive's {nv} vertices")
                    mnrm[ti] = d
            dw = np.zeros(k)
            if default_w is not None and k:
                got = gltf_checks.float_array(default_w)
                if got is None or got.shape[0] != k or not np.all(np.isfinite(got)):
                    raise r.err(f"meshes[{mi}].weights", f"expected {k} finite morph weights")
                dw = got
            tex, color = material(prim.material, field + ".material")
            minfo = gltf_ext.material_info(r, prim.material, field + ".material")  # alpha, sides, UV transform
            if uv is not None:
                uv = gltf_ext.apply_uv_transform(uv, minfo.uv_transform)
            # placement
            joints: np.ndarray | None
            if skin_i is not None and has_skeleton:
                j, w = _skin_attributes(r, attrs, nv, len(skins[skin_i].joints), field)
                if j is None:
                    raise r.err(field + ".attributes.JOINTS_0", f"is missing although nodes[{ni}] has a skin")
                joints = skin_bones[skin_i][j]
                skinned = True
            else:
                wm = node_world[ni]
                if has_skeleton and gltf_checks.singular(wm):  # zero scale: node space, inverse bind = I
                    wm = np.eye(4)
                pos = transform_points(wm, pos)
                if k:
                    mpos = transform_vectors(wm, mpos)
                nm = gltf_checks.normal_matrix(wm)  # inverse transpose, finite for zero scale
                if nrm is not None:
                    nrm = nrm @ nm.T
                    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
                    nrm = np.where(ln > 0, nrm / np.where(ln > 0, ln, 1), nrm)
                if k:
                    mnrm = mnrm @ nm.T
                if np.linalg.det(wm[:3, :3]) < 0:
                    tri = tri[:, ::-1].copy()
                if has_skeleton:
                    joints = np.zeros((nv, 4), np.int64)
                    joints[:, 0] = bone_of_node[ni]
                    w = np.zeros((nv, 4))
                    w[:, 0] = 1.0
                    skinned = True
                else:
                    joints, w, skinned = None, None, False
            name = group if len(prims) == 1 else f"{group}/{pi}"
            if uses.get(mi, 0) > 1:
                name = f"{node_names[ni]}:{name}"
            meshes.append(SkinnedMesh(
                # None normals / uv / joints / weights: SkinnedMesh.__post_init__ makes the defaults
                name=name, positions=pos, indices=tri, normals=nrm, uv=uv, joints=joints, weights=w,  # type: ignore[arg-type]
                morph_positions=mpos, morph_normals=mnrm, morph_names=[str(x) for x in tnames][:k],
                morph_default_weights=dw, texture=tex, base_color=color, skinned=skinned, group=group,
                material=minfo))
    names_seen = _unique([m.name for m in meshes])
    for m, n in zip(meshes, names_seen):
        m.name = n

    # ---------------------------------------------------------------- animations
    clips = {}
    clip_names = _unique([a.name if a.name else f"animation{i}" for i, a in enumerate(animations)])
    for ai, a in enumerate(animations):
        samplers = a.samplers or []
        tracks: dict = {}
        wtracks: dict = {}
        wmesh: dict = {}
        duration = 0.0
        for ci, ch in enumerate(a.channels or []):
            tgt = ch.target
            if tgt is None or tgt.node is None or tgt.path not in ("translation", "rotation", "scale", "weights"):
                continue
            cf = f"animations[{ai}].channels[{ci}]"
            if not isinstance(ch.sampler, int) or not 0 <= ch.sampler < len(samplers):
                raise r.err(cf + ".sampler", f"refers to sampler {ch.sampler!r} but the animation has {len(samplers)}")
            smp = samplers[ch.sampler]
            sf = f"animations[{ai}].samplers[{ch.sampler}]"
            interp = smp.interpolation or "LINEAR"
            if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
                raise r.err(sf + ".interpolation", f"is {interp!r}, expected LINEAR, STEP or CUBICSPLINE")
            times = r.accessor(smp.input, sf + ".input", types=("SCALAR",), comps=(_FLOAT,)).reshape(-1)
            if times.size == 0:
                continue
            if np.any(np.diff(times) < 0):
                raise r.err(sf + ".input", "key times are not increasing")
            if times[0] < 0:
                raise r.err(sf + ".input", "negative key time")
            tpath = tgt.path
            if tpath == "weights":
                node = nodes[tgt.node]
                if node.mesh is None:
                    raise r.err(cf + ".target.node", "animates morph weights of a node without a mesh")
                mesh = r.item("meshes", node.mesh, f"nodes[{tgt.node}].mesh")
                k = max((len(p.targets or []) for p in mesh.primitives or []), default=0)
                if k == 0:
                    raise r.err(cf + ".target.node", "animates morph weights of a mesh without morph targets")
                out = r.accessor(smp.output, sf + ".output", types=("SCALAR",), comps=(_FLOAT, 5120, 5121, 5122, 5123))
                c = k
            else:
                c = 4 if tpath == "rotation" else 3
                comps = (_FLOAT, 5120, 5121, 5122, 5123) if tpath == "rotation" else (_FLOAT,)
                out = r.accessor(smp.output, sf + ".output", types=("VEC4" if c == 4 else "VEC3",), comps=comps)
            n = times.size
            mult = 3 if interp == "CUBICSPLINE" else 1
            if out.size != n * c * mult:
                raise r.err(sf + ".output", f"has {out.size // c if c else 0} values of {c}, expected {n * mult} "
                                            f"for {n} key times ({interp})")
            out = out.reshape(n, mult, c)
            if mult == 3:
                tr = Track(times, out[:, 1], interp, in_tangents=out[:, 0], out_tangents=out[:, 2])
            else:
                vals = out[:, 0]
                if tpath == "rotation":
                    ln = np.linalg.norm(vals, axis=1, keepdims=True)
                    if np.any(ln < 1e-8):
                        raise r.err(sf + ".output", "zero-length rotation quaternion")
                    vals = vals / ln
                tr = Track(times, vals, interp)
            duration = max(duration, float(times[-1]))
            if tpath == "weights":
                key = group_names[nodes[tgt.node].mesh]
                wtracks[key] = tr
                wmesh[int(nodes[tgt.node].mesh)] = key
            else:
                if not has_skeleton or tgt.node not in bone_of_node:
                    continue  # node outside the scene
                assert skeleton is not None  # built whenever has_skeleton
                bname = skeleton.names[bone_of_node[tgt.node]]
                tracks.setdefault(bname, {})[tpath] = tr
        clips[clip_names[ai]] = Clip(clip_names[ai], duration, tracks, wtracks, skeleton=skeleton,
                                     weight_track_mesh_index=wmesh)

    # ---------------------------------------------------------------- lights and cameras
    lights: list[Any] = []
    cameras: list[Any] = []
    ext = g.extensions if isinstance(g.extensions, dict) else {}
    lpx = ext.get("KHR_lights_punctual")
    light_defs = (lpx.get("lights") if isinstance(lpx, dict) else None) or []
    if not isinstance(light_defs, list):
        raise r.err("extensions.KHR_lights_punctual.lights", f"expected an array, got {type(light_defs).__name__}")
    for i in np.flatnonzero(in_scene).tolist():
        n = nodes[i]
        wm = node_world[i]
        pos = wm[:3, 3].copy()
        fwd = -wm[:3, 2]
        fwd = fwd / max(np.linalg.norm(fwd), 1e-30)
        up = wm[:3, 1] / max(np.linalg.norm(wm[:3, 1]), 1e-30)
        nex = n.extensions if isinstance(n.extensions, dict) else {}
        if "KHR_lights_punctual" in nex:
            nlx = nex["KHR_lights_punctual"]
            li = nlx.get("light") if isinstance(nlx, dict) else None
            if not isinstance(li, int) or not 0 <= li < len(light_defs):
                raise r.err(f"nodes[{i}].extensions.KHR_lights_punctual.light",
                            f"refers to light {li!r} but the file has {len(light_defs)}")
            lf = gltf_checks.light_fields(path, f"extensions.KHR_lights_punctual.lights[{li}]", light_defs[li])
            lf["name"] = lf["name"] or node_names[i]
            try:
                lights.append(light_from_gltf(lf, pos, fwd, frame, len(lights)))
            except ValidationError as exc:  # e.g. a candela value no piste light can hold at that range
                raise r.err(f"extensions.KHR_lights_punctual.lights[{li}]", str(exc)) from None
        if n.camera is not None:
            c = r.item("cameras", n.camera, f"nodes[{i}].camera")
            cfield, num = f"cameras[{n.camera}]", gltf_checks.number
            if c.type == "orthographic" and c.orthographic is not None:
                o, of = c.orthographic, cfield + ".orthographic"
                znear = num(path, of + ".znear", o.znear, 0.0, 0.0)
                cdoc = {"name": c.name or node_names[i], "type": "orthographic", "znear": znear,
                      "zfar": num(path, of + ".zfar", o.zfar, lo=znear, lo_open=True),
                      "xmag": num(path, of + ".xmag", o.xmag), "ymag": num(path, of + ".ymag", o.ymag)}
                cameras.append(camera_from_gltf(cdoc, pos, fwd, up, frame, len(cameras)))
            else:
                p = c.perspective
                if p is None:
                    raise r.err(f"cameras[{n.camera}].perspective", "is missing")
                pf = cfield + ".perspective"
                znear = num(path, pf + ".znear", p.znear, lo=0.0, lo_open=True)
                cdoc = {"name": c.name or node_names[i], "type": "perspective",
                      "yfov": num(path, pf + ".yfov", p.yfov, lo=0.0, hi=np.pi, lo_open=True, hi_open=True),
                      "aspect": None if p.aspectRatio is None else num(path, pf + ".aspectRatio", p.aspectRatio,
                                                                       lo=0.0, lo_open=True),
                      "znear": znear,
                      "zfar": None if p.zfar is None else num(path, pf + ".zfar", p.zfar, lo=znear, lo_open=True)}
                cameras.append(camera_from_gltf(cdoc, pos, fwd, up, frame, len(cameras)))

    return Model(name=path.stem, skeleton=skeleton, meshes=meshes, clips=clips, lights=lights, cameras=cameras,
                 path=str(path))
