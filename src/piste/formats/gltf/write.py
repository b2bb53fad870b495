"""glTF 2.0 export (``.glb`` or ``.gltf`` + ``.bin``) of what piste computes, with pygltflib.

Everything here takes plain arrays (a tessellated terrain mesh, not a patch net: the terrain is
tessellated by :func:`piste.terrain.tessellate.terrain_mesh`) and the character data classes, so a
scene, a built bundle or an SSX level can all be written by the same code (the bundle glue is
:mod:`piste.pipeline.bundle_gltf`).  This module imports no terrain code.

Conventions
-----------
- **Axes.** piste is right-handed +Z up (Blender's axes); glTF is +Y up.  All content hangs under
  one root node ``piste`` whose rotation (-90 degrees about X) maps piste ``(x, y, z)`` to glTF
  ``(x, z, -y)``; vertex data and node transforms below it stay in piste's coordinates.  Blender's
  importer applies the inverse, so the objects land at piste's own coordinates again.  Skinned mesh
  nodes are scene roots (glTF ignores a skinned mesh node's transform; their joints carry it).
- **Terrain**: one mesh, one primitive: ``POSITION``, ``NORMAL`` (unit), ``TEXCOORD_0`` (the base
  texture's UVs, repeating), ``TEXCOORD_1`` (the light-map atlas UVs, one tile per patch).
  The material's ``baseColorTexture`` (texCoord 0) is the base texture when one is given and its
  **``occlusionTexture`` on texCoord 1 is the light-map atlas**: the slot that Blender
  (glTF Settings node), three.js (``aoMap``, which reads ``uv1``/``uv2``), Babylon.js and
  Godot read with a second UV set.  The atlas is stored as an 8-bit linear RGB PNG
  ``round(255 * clamp(light / scale, 0, 1))`` (``scale`` 1.0 by default, so light above 1.0
  saturates); viewers that use it as ambient occlusion read the red channel.  The material's
  ``extras.piste_lightmap`` records ``{"texture", "texCoord": 1, "scale", "encoding": "linear"}``
  so a reader can multiply ``base x light`` as piste does.  Row 0 of the atlas is ``v = 0`` in
  both piste and glTF, so no flip.
- **Characters**: every bone is a node (names ``prefix + bone``) holding its *rest* TRS; the skin
  lists all bones in skeleton order, so ``JOINTS_0`` are the skeleton's bone indices; the inverse
  bind matrices are the model's (``Skeleton.inverse_bind``), so a skeleton whose bind pose is its
  rest pose (the default rider, checked by the tests) shows the undeformed mesh when no clip
  plays.  Morph targets keep ``POSITION``/``NORMAL`` deltas, names in ``extras.targetNames`` and
  default weights.  Clips become animations (``prefix + clip``) with their own interpolation
  (CUBICSPLINE tangents kept); identical key-time arrays share one accessor.
- **Objects** (instances of a few meshes): ``instancing="ext"`` writes one node per mesh kind with
  ``EXT_mesh_gpu_instancing`` (TRANSLATION/ROTATION/SCALE per instance; the extension is *used*,
  not *required*: a viewer without it draws one instance); ``"nodes"`` writes one plain node per
  instance sharing the mesh (the fallback every viewer reads).  An instance matrix that is not a
  TRS (shear) cannot be expressed by either: its geometry is baked into a mesh of its own.
- **Lights** (``KHR_lights_punctual``) and **cameras** are piste's own (:mod:`piste.scene_data`:
  lights in relative units, :class:`~piste.scene_data.Camera`) in piste's world coordinates;
  :mod:`piste.formats.gltf.units` converts them to glTF's (lux, candela, radians; ``white`` lux
  is 1.0).  Ambient and negative lights have no glTF form and are left out
  (:func:`piste.formats.gltf.units.lights_without_gltf_form` lists them for the scene's extras).
- Output is written atomically (a ``.gltf``'s ``.bin`` first, then the JSON): a failed export
  leaves no partial file.

API
---
::

    TerrainExport(mesh, lightmap=None, base_texture=None, lightmap_scale=1.0, name="terrain")
    (mesh: piste.terrain.tessellate.terrain_mesh(net, level=4))
    CharacterExport(model, matrix=eye(4), name="character", clips=None, prefix="")
    ObjectsExport(meshes, kinds, kind, matrix, texture=None)
    export_gltf(path, terrain=None, characters=(), objects=None, lights=(), cameras=(), instancing="ext",
                extras=None, up="y", white=683.0) -> ExportReport
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, ValidationError
from piste.formats.atomic import atomic_path, write_bytes_atomic
from piste.formats.gltf import units as gltf_units
from piste.scene_data import AnyLight, Camera
from piste.transforms import compose_trs, decompose_trs, look_rotation

if TYPE_CHECKING:  # (types only: writing a file without characters does not import them)
    from piste.character.model import Model

__all__ = ["TerrainExport", "CharacterExport", "ObjectsExport", "ExportReport", "export_gltf",
           "lightmap_to_png_array", "Y_UP_ROOT_ROTATION"]

#: xyzw rotation of the root node: piste (x, y, z) Z-up -> glTF (x, z, -y) Y-up (-90 degrees about X)
Y_UP_ROOT_ROTATION = (-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT, _UBYTE, _USHORT, _UINT = 5126, 5121, 5123, 5125
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


@dataclass
class TerrainExport:
    """Terrain to export.

    Attributes
    ----------
    mesh : TerrainMesh
        The tessellated terrain (:func:`piste.terrain.tessellate.terrain_mesh`; a
        :class:`~piste.terrain.tessellate.TerrainMesh`: ``positions (v, 3)``, ``normals (v, 3)``,
        ``uv (v, 2)``, ``uv_lightmap (v, 2)``, ``indices (t, 3)``, ``patch_ids``, ``patch_levels``).
    lightmap : ndarray or None
        ``(H, W, 3|4)`` float (linear light, 1.0 = white) or uint8 (255 = 1.0) atlas addressed by
        the mesh's ``uv_lightmap`` (the net's ``lightmap_rect``), or None.
    base_texture : ndarray or None
        ``(h, w, 3|4)`` uint8, or None.
    lightmap_scale : float
        The light value stored as 255 (float atlases).
    """

    mesh: Any  # piste.terrain's TerrainMesh (formats does not import terrain: typed by what it has)
    lightmap: np.ndarray | None = None
    base_texture: np.ndarray | None = None
    lightmap_scale: float = 1.0
    name: str = "terrain"


@dataclass
class CharacterExport:
    """A character (skeleton, skinned meshes, morphs, clips) placed by ``matrix (4, 4)`` (character -> world).

    ``clips``: names of the model's clips to export (None: all); ``prefix`` is put before every
    bone, mesh and clip name (several characters in one file); ``extras`` go on the character node.
    """

    model: Model
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    name: str = "character"
    clips: list | None = None
    prefix: str = ""
    extras: dict | None = None


@dataclass
class ObjectsExport:
    """Instanced objects: ``meshes {kind: (positions (v,3), normals (v,3), uv (v,2), indices (t,3))}``,
    ``kinds`` tuple, ``kind (n,) int`` index into ``kinds``, ``matrix (n, 4, 4)`` object -> world,
    ``texture (H, W, 4) uint8`` shared base-colour texture (or None), ``names`` optional (n,)."""

    meshes: dict
    kinds: tuple
    kind: np.ndarray
    matrix: np.ndarray
    texture: np.ndarray | None = None
    names: list | None = None


@dataclass
class ExportReport:
    """What :func:`export_gltf` wrote: ``path``, ``bytes``, counts, and ``nodes`` by role."""

    path: Path
    bytes: int
    terrain_triangles: int = 0
    terrain_vertices: int = 0
    characters: int = 0
    animations: int = 0
    objects: int = 0
    baked_objects: int = 0
    lights: int = 0
    cameras: int = 0
    files: list = field(default_factory=list)


# ---------------------------------------------------------------------------------------------
def lightmap_to_png_array(atlas: npt.ArrayLike, scale: float = 1.0) -> np.ndarray:
    """``(H, W, 3) uint8`` of a light-map atlas: float light -> ``round(255 clamp(light / scale))``;
    uint8 atlases are passed through (RGB)."""
    a = np.asarray(atlas)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValidationError(f"light-map atlas must be (H, W, 3|4), got shape {a.shape}")
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a[..., :3])
    if not scale > 0:
        raise ValidationError(f"lightmap_scale must be > 0, got {scale}")
    return np.round(np.clip(a[..., :3].astype(np.float64) / scale, 0.0, 1.0) * 255.0).astype(np.uint8)


def _png(image: npt.ArrayLike) -> bytes:
    from PIL import Image

    a = np.ascontiguousarray(np.asarray(image))
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValidationError(f"textures must be (h, w, 3|4) uint8, got {a.dtype} {a.shape}")
    buf = io.BytesIO()
    Image.fromarray(a, "RGBA" if a.shape[2] == 4 else "RGB").save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def _quat_looking(forward: npt.ArrayLike, up: npt.ArrayLike) -> list:
    """Node rotation xyzw whose -Z is ``forward`` and +Y is (nearly) ``up`` (Y-up file axes)."""
    return look_rotation(forward, up, fallback=(0.0, 1.0, 0.0))


def _trs(matrix: npt.ArrayLike, tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """``(t, r, s, ok)`` of an affine matrix; ``ok`` False when it has shear (not a TRS)."""
    m = np.asarray(matrix, dtype=np.float64)
    t, r, s = decompose_trs(m)
    r = r / np.linalg.norm(r, axis=-1, keepdims=True)
    back = compose_trs(t, r, s)
    scale = max(1.0, float(np.abs(m[..., :3, :3]).max()))
    err = np.abs(back[..., :3, :3] - m[..., :3, :3]).reshape(*m.shape[:-2], 9).max(axis=-1)
    return t, r, s, err <= tol * scale


class _Builder:
    """Accumulates one binary buffer and the glTF lists."""

    def __init__(self) -> None:
        import pygltflib

        self.G = pygltflib
        self.blob = bytearray()
        self.g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0", generator="piste gltf_export"))
        self.g.buffers, self.g.bufferViews, self.g.accessors = [], [], []
        self.g.nodes, self.g.meshes, self.g.materials = [], [], []
        self.g.textures, self.g.images, self.g.samplers, self.g.skins = [], [], [], []
        self.g.animations, self.g.cameras = [], []
        self.used: set[str] = set()
        self._times: dict[bytes, int] = {}
        self._images: dict[int, int] = {}

    def view(self, data: bytes, target: int | None = None, stride: int | None = None) -> int:
        pad = (-len(self.blob)) % 4
        self.blob.extend(b"\0" * pad)
        off = len(self.blob)
        self.blob.extend(data)
        self.g.bufferViews.append(self.G.BufferView(buffer=0, byteOffset=off, byteLength=len(data), target=target,
                                                    byteStride=stride))
        return len(self.g.bufferViews) - 1

    def accessor(self, arr: npt.ArrayLike, ctype: int = _FLOAT, target: int | None = None, minmax: bool = False,
                 normalized: bool = False, mat4: bool = False) -> int:
        arr = np.asarray(arr)
        dt = {_FLOAT: "<f4", _UBYTE: "u1", _USHORT: "<u2", _UINT: "<u4"}[ctype]
        if mat4:
            a = np.ascontiguousarray(np.swapaxes(arr, -1, -2).reshape(-1, 16), dtype=dt)  # column-major
            nc = 16
        else:
            a = np.ascontiguousarray(arr, dtype=dt)
            a = a.reshape(a.shape[0], -1) if a.ndim > 1 else a.reshape(-1, 1)
            nc = a.shape[1]
        if ctype == _FLOAT and not np.all(np.isfinite(a)):
            raise ValidationError("cannot export non-finite values (NaN or infinity)")
        # vertex attributes must have 4-byte-aligned elements; pad byte/short VEC3 etc. via stride
        elem = a.dtype.itemsize * nc
        stride = None
        data = a.tobytes()
        if target == _ARRAY_BUFFER and elem % 4:
            stride = elem + (-elem) % 4
            padded = np.zeros((a.shape[0], stride), np.uint8)
            padded[:, :elem] = a.view(np.uint8).reshape(a.shape[0], elem)
            data = padded.tobytes()
        bv = self.view(data, target=target, stride=stride)
        acc = self.G.Accessor(bufferView=bv, byteOffset=0, componentType=ctype, count=int(a.shape[0]),
                              type=_TYPES[nc], normalized=True if normalized else None)
        if minmax and a.shape[0]:
            if ctype == _FLOAT:
                acc.min = [float(x) for x in a.min(axis=0)]
                acc.max = [float(x) for x in a.max(axis=0)]
            else:
                acc.min = [int(x) for x in a.min(axis=0)]
                acc.max = [int(x) for x in a.max(axis=0)]
        self.g.accessors.append(acc)
        return len(self.g.accessors) - 1

    def indices(self, tri: npt.ArrayLike, n_vertices: int) -> int:
        flat = np.asarray(tri, dtype=np.int64).reshape(-1)
        return self.accessor(flat, _USHORT if n_vertices <= 65535 else _UINT, target=_ELEMENT_ARRAY_BUFFER)

    def times(self, t: npt.ArrayLike) -> int:
        a = np.ascontiguousarray(t, dtype="<f4")
        key = a.tobytes()
        if key not in self._times:
            self._times[key] = self.accessor(a, minmax=True)
        return self._times[key]

    def texture(self, image: npt.ArrayLike, key: int | None = None) -> int:
        k = id(image) if key is None else key
        if k in self._images:
            return self._images[k]
        bv = self.view(_png(image))
        self.g.images.append(self.G.Image(bufferView=bv, mimeType="image/png"))
        if not self.g.samplers:
            self.g.samplers.append(self.G.Sampler(magFilter=9729, minFilter=9987, wrapS=10497, wrapT=10497))
        self.g.textures.append(self.G.Texture(source=len(self.g.images) - 1, sampler=0))
        self._images[k] = len(self.g.textures) - 1
        return self._images[k]

    def node(self, **kw: Any) -> int:
        self.g.nodes.append(self.G.Node(**kw))
        return len(self.g.nodes) - 1

    def mesh(self, name: str, prims: list, weights: list | None = None, extras: dict | None = None) -> int:
        self.g.meshes.append(self.G.Mesh(name=name, primitives=prims, weights=weights, extras=extras or {}))
        return len(self.g.meshes) - 1

    def material(self, **kw: Any) -> int:
        self.g.materials.append(self.G.Material(**kw))
        return len(self.g.materials) - 1


def _unit_normals(n: npt.ArrayLike, fallback: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    n = np.asarray(n, dtype=np.float64)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(ln > 1e-12, n / np.where(ln > 1e-12, ln, 1.0), np.asarray(fallback))
    return out.astype(np.float32)


def _pbr(b: _Builder, base_color: np.ndarray | None = None, tex: int | None = None) -> Any:
    return b.G.PbrMetallicRoughness(
        baseColorFactor=None if base_color is None else [float(x) for x in base_color],
        baseColorTexture=None if tex is None else b.G.TextureInfo(index=tex), metallicFactor=0.0, roughnessFactor=1.0)


# ---------------------------------------------------------------------------------------------
def _add_terrain(b: _Builder, t: TerrainExport, root_children: list, report: ExportReport) -> None:
    mesh = t.mesh
    nv = mesh.n_vertices
    attrs = b.G.Attributes(POSITION=b.accessor(mesh.positions, target=_ARRAY_BUFFER, minmax=True),
                           NORMAL=b.accessor(_unit_normals(mesh.normals), target=_ARRAY_BUFFER),
                           TEXCOORD_0=b.accessor(mesh.uv, target=_ARRAY_BUFFER),
                           TEXCOORD_1=b.accessor(mesh.uv_lightmap, target=_ARRAY_BUFFER))
    mat = {"name": f"{t.name} material", "doubleSided": False}
    base_tex = b.texture(t.base_texture) if t.base_texture is not None else None
    mat["pbrMetallicRoughness"] = _pbr(b, None, base_tex)
    if t.lightmap is not None:
        lm = b.texture(lightmap_to_png_array(t.lightmap, t.lightmap_scale))
        mat["occlusionTexture"] = b.G.OcclusionTextureInfo(index=lm, texCoord=1, strength=1.0)
        mat["extras"] = {"piste_lightmap": {"texture": lm, "texCoord": 1, "scale": float(t.lightmap_scale),
                                            "encoding": "linear"}}
    mi = b.material(**mat)
    prim = b.G.Primitive(attributes=attrs, indices=b.indices(mesh.indices, nv), material=mi, mode=4)
    levels = np.unique(np.asarray(mesh.patch_levels)).tolist()
    m = b.mesh(t.name, [prim], extras={"piste": {"patches": int(len(mesh.patch_ids)), "levels": levels}})
    root_children.append(b.node(name=t.name, mesh=m))
    report.terrain_triangles += mesh.n_triangles
    report.terrain_vertices += nv


def _add_character(b: _Builder, c: CharacterExport, root_children: list, scene_roots: list,
                   report: ExportReport) -> None:
    model = c.model
    sk = model.skeleton
    p = c.prefix
    t, r, s, ok = _trs(c.matrix)
    if not ok:
        raise ValidationError(f"character {c.name!r}: its placement matrix has shear (not a translation, rotation, scale)")
    char_node = b.node(name=c.name, translation=[float(x) for x in t], rotation=[float(x) for x in r],
                       scale=[float(x) for x in s], children=[], extras=c.extras or {})
    root_children.append(char_node)
    bone_nodes = []
    if sk is not None:
        for i, name in enumerate(sk.names):
            bone_nodes.append(b.node(name=p + name, translation=[float(x) for x in sk.rest_translation[i]],
                                     rotation=[float(x) for x in sk.rest_rotation[i]],
                                     scale=[float(x) for x in sk.rest_scale[i]], children=[]))
        for i, par in enumerate(sk.parents):
            (b.g.nodes[bone_nodes[par]].children if par >= 0 else b.g.nodes[char_node].children).append(bone_nodes[i])
        roots = [bone_nodes[i] for i in np.flatnonzero(sk.parents < 0)]
        ibm = b.accessor(sk.inverse_bind, mat4=True)
        b.g.skins.append(b.G.Skin(name=p + (model.name or "skin"), inverseBindMatrices=ibm, joints=bone_nodes,
                                  skeleton=roots[0] if len(roots) == 1 else char_node))
        skin_i = len(b.g.skins) - 1
    # meshes: primitives of one glTF mesh group share a mesh
    groups: dict[str, list] = {}
    for m in model.meshes:
        groups.setdefault(m.group or m.name, []).append(m)
    mesh_node_of_group = {}
    for gname, ms in groups.items():
        prims = []
        k = ms[0].n_morphs
        names = list(ms[0].morph_names)
        for m in ms:
            nv = m.n_vertices
            if m.n_morphs != k:
                raise ValidationError(f"character {c.name!r}: primitives of mesh {gname!r} have different morph counts")
            attrs = b.G.Attributes(POSITION=b.accessor(m.positions, target=_ARRAY_BUFFER, minmax=True),
                                   NORMAL=b.accessor(_unit_normals(m.normals), target=_ARRAY_BUFFER),
                                   TEXCOORD_0=b.accessor(m.uv, target=_ARRAY_BUFFER))
            if sk is not None and m.skinned:
                w = np.asarray(m.weights, np.float32)
                j = np.asarray(m.joints, np.int64)
                j = np.where(w > 0, j, 0)
                ws = w.sum(axis=1, keepdims=True)
                w = np.where(ws > 0, w / np.where(ws > 0, ws, 1), np.array([1.0, 0, 0, 0], np.float32)).astype(np.float32)
                attrs.JOINTS_0 = b.accessor(j, _USHORT if sk.n_bones > 255 else _UBYTE, target=_ARRAY_BUFFER)
                attrs.WEIGHTS_0 = b.accessor(w, target=_ARRAY_BUFFER)
            targets = []
            for ti in range(k):
                targets.append({"POSITION": b.accessor(m.morph_positions[ti], target=_ARRAY_BUFFER, minmax=True),
                                "NORMAL": b.accessor(m.morph_normals[ti], target=_ARRAY_BUFFER)})
            tex = b.texture(m.texture) if m.texture is not None else None
            info = getattr(m, "material", None)  # an imported glTF material (piste.formats.gltf.extensions.MaterialInfo)
            mode = getattr(info, "alpha_mode", None) or ("BLEND" if float(m.base_color[3]) < 1.0 else "OPAQUE")
            mat = b.material(name=p + m.name, pbrMetallicRoughness=_pbr(b, m.base_color, tex), alphaMode=mode,
                             alphaCutoff=float(info.alpha_cutoff) if mode == "MASK" and info is not None else None,
                             doubleSided=bool(getattr(info, "double_sided", False)) or None)
            prims.append(b.G.Primitive(attributes=attrs, indices=b.indices(m.indices, nv), material=mat, mode=4,
                                       targets=targets or None))
        extras = {"targetNames": names} if k else None
        mi = b.mesh(p + gname, prims, weights=[float(x) for x in ms[0].morph_default_weights] if k else None,
                    extras=extras)
        if sk is not None and all(m.skinned for m in ms):
            n = b.node(name=p + gname, mesh=mi, skin=skin_i)
            scene_roots.append(n)
        else:
            n = b.node(name=p + gname, mesh=mi)
            if b.g.nodes[char_node].children is None:
                b.g.nodes[char_node].children = []
            b.g.nodes[char_node].children.append(n)
        mesh_node_of_group[gname] = n
    # clips
    names = list(model.clips) if c.clips is None else list(c.clips)
    for cname in names:
        if cname not in model.clips:
            raise ConfigError(f"character {c.name!r} has no clip {cname!r} (clips: {', '.join(model.clips) or 'none'})")
        clip = model.clips[cname]
        samplers: list = []
        channels: list = []

        def add(track: Any, node: int, path: str, samplers: list = samplers, channels: list = channels) -> None:  # this clip's lists
            vals = np.asarray(track.values, dtype=np.float64)
            if track.interpolation == "CUBICSPLINE":
                out = np.stack([track.in_tangents, vals, track.out_tangents], axis=1).reshape(-1, vals.shape[1])
            else:
                out = vals
            if path == "weights":
                out = out.reshape(-1, 1)
            samplers.append(b.G.AnimationSampler(input=b.times(track.times), output=b.accessor(out),
                                                 interpolation=track.interpolation))
            channels.append(b.G.AnimationChannel(sampler=len(samplers) - 1,
                                                 target=b.G.AnimationChannelTarget(node=node, path=path)))

        for bone, tracks in clip.tracks.items():
            bi = sk.get(bone) if sk is not None else None
            if bi is None:
                continue
            for path in ("translation", "rotation", "scale"):
                if path in tracks:
                    add(tracks[path], bone_nodes[bi], path)
        for mname, tr in clip.weight_tracks.items():
            if mname in mesh_node_of_group:
                add(tr, mesh_node_of_group[mname], "weights")
        if channels:
            b.g.animations.append(b.G.Animation(name=p + cname, samplers=samplers, channels=channels))
            report.animations += 1
    report.characters += 1


def _add_objects(b: _Builder, o: ObjectsExport, instancing: str, root_children: list, report: ExportReport) -> None:
    kinds = tuple(o.kinds)
    kind = np.asarray(o.kind, dtype=np.int64).reshape(-1)
    mats = np.asarray(o.matrix, dtype=np.float64).reshape(-1, 4, 4)
    if kind.shape[0] != mats.shape[0]:
        raise ValidationError(f"objects: {kind.shape[0]} kinds but {mats.shape[0]} matrices")
    if kind.size and (kind.min() < 0 or kind.max() >= len(kinds)):
        raise ValidationError(f"objects: kind index out of range for {len(kinds)} kinds")
    tex = b.texture(o.texture) if o.texture is not None else None
    cut = o.texture is not None and np.asarray(o.texture).shape[-1] == 4 and int(np.asarray(o.texture)[..., 3].min()) < 255
    mat = b.material(name="objects", pbrMetallicRoughness=_pbr(b, None, tex),  # alpha: pipeline.object_atlas's cut-outs
                     alphaMode="MASK" if cut else None, alphaCutoff=0.5 if cut else None)
    t, r, s, ok = _trs(mats) if len(mats) else (np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros(0, bool))
    names = list(o.names) if o.names is not None else [f"{kinds[k]}{i}" for i, k in enumerate(kind)]

    def prim(pos: np.ndarray, nrm: np.ndarray, uv: np.ndarray, tri: np.ndarray) -> Any:
        attrs = b.G.Attributes(POSITION=b.accessor(pos, target=_ARRAY_BUFFER, minmax=True),
                               NORMAL=b.accessor(_unit_normals(nrm), target=_ARRAY_BUFFER),
                               TEXCOORD_0=b.accessor(uv, target=_ARRAY_BUFFER))
        return b.G.Primitive(attributes=attrs, indices=b.indices(tri, len(pos)), material=mat, mode=4)

    for ki, kname in enumerate(kinds):
        pos, nrm, uv, tri = (np.asarray(x) for x in o.meshes[kname])
        inst = np.flatnonzero(kind == ki)
        trs_inst = inst[ok[inst]]
        if trs_inst.size:
            mi = b.mesh(kname, [prim(pos, nrm, uv, tri)])
            if instancing == "ext":
                ext = {"attributes": {"TRANSLATION": b.accessor(t[trs_inst], target=_ARRAY_BUFFER),
                                      "ROTATION": b.accessor(r[trs_inst], target=_ARRAY_BUFFER),
                                      "SCALE": b.accessor(s[trs_inst], target=_ARRAY_BUFFER)}}
                root_children.append(b.node(name=f"{kname} instances", mesh=mi,
                                            extensions={"EXT_mesh_gpu_instancing": ext},
                                            extras={"instances": [names[i] for i in trs_inst]}))
                b.used.add("EXT_mesh_gpu_instancing")
            else:
                for i in trs_inst:
                    root_children.append(b.node(name=names[i], mesh=mi, translation=[float(x) for x in t[i]],
                                                rotation=[float(x) for x in r[i]], scale=[float(x) for x in s[i]]))
        for i in inst[~ok[inst]]:  # sheared: bake the instance's geometry
            m = mats[i]
            nm = np.linalg.inv(m[:3, :3]).T
            p2 = pos.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
            tri2 = tri[:, ::-1] if np.linalg.det(m[:3, :3]) < 0 else tri
            mi = b.mesh(names[i], [prim(p2, nrm.astype(np.float64) @ nm.T, uv, tri2)])
            root_children.append(b.node(name=names[i], mesh=mi))
            report.baked_objects += 1
    report.objects += int(len(kind))


def _add_lights(b: _Builder, lights: Iterable[AnyLight], root_children: list, report: ExportReport, white: float) -> None:
    defs: list[dict[str, Any]] = []
    for i, li in enumerate(lights):
        d = gltf_units.light_to_gltf(li, white, i)  # piste's units -> lux / candela (None: ambient or negative)
        if d is None:
            continue
        position, direction = d.pop("position", None), d.pop("direction")
        up = (0.0, 0.0, 1.0) if abs(direction[2]) < 0.99 * np.linalg.norm(direction) else (0.0, 1.0, 0.0)
        kw = {"name": d["name"], "extensions": {"KHR_lights_punctual": {"light": len(defs)}}}
        defs.append(d)
        if d["type"] != "point":
            kw["rotation"] = _quat_looking(direction, up)
        if d["type"] != "directional":
            kw["translation"] = [float(x) for x in np.asarray(position).reshape(3)]
        root_children.append(b.node(**kw))
    if defs:
        b.used.add("KHR_lights_punctual")
        b.g.extensions = dict(b.g.extensions or {})
        b.g.extensions["KHR_lights_punctual"] = {"lights": defs}
    report.lights += len(defs)


def _add_cameras(b: _Builder, cameras: Iterable[Camera], root_children: list, report: ExportReport) -> None:
    for c in cameras:
        f = gltf_units.camera_to_gltf(c)
        zfar = f["zfar"]
        if f["type"] == "orthographic":
            ymag = float(f["ymag"] or 1.0)
            xmag = float(f["xmag"] or ymag * (f["aspect"] or 1.0))
            cam = b.G.Camera(name=f["name"], type="orthographic",
                             orthographic=b.G.Orthographic(xmag=xmag, ymag=ymag, znear=float(f["znear"]),
                                                           zfar=zfar if zfar is not None else 4000.0))
        else:
            cam = b.G.Camera(name=f["name"], type="perspective",
                             perspective=b.G.Perspective(yfov=float(f["yfov"]), znear=max(float(f["znear"]), 1e-6),
                                                         zfar=zfar, aspectRatio=float(f["aspect"])))
        b.g.cameras.append(cam)
        root_children.append(b.node(name=f["name"], camera=len(b.g.cameras) - 1,
                                    translation=[float(x) for x in f["position"]],
                                    rotation=_quat_looking(f["forward"], f["up"])))
        report.cameras += 1


# ---------------------------------------------------------------------------------------------
def export_gltf(path: str | os.PathLike[str], terrain: TerrainExport | None = None, characters: Iterable[CharacterExport] = (),
                objects: ObjectsExport | None = None, lights: Iterable[AnyLight] = (), cameras: Iterable[Camera] = (), instancing: str = "ext", extras: dict | None = None,
                up: str = "y", white: float = gltf_units.DEFAULT_WHITE_LUX) -> ExportReport:
    """Write a glTF 2.0 file: ``.glb`` (one file) or ``.gltf`` (JSON + ``<stem>.bin``), atomically.

    ``terrain``, ``characters`` (CharacterExport list), ``objects`` (ObjectsExport), ``lights``
    (piste lights, any iterable: a :class:`piste.scene_data.Lights` or a list; ``white`` lux is 1.0)
    and ``cameras`` (:class:`piste.scene_data.Camera` list, named), all in piste's world coordinates.  ``instancing`` "ext" (EXT_mesh_gpu_instancing) or
    "nodes"; ``up`` "y" (the root node turns piste's Z up into glTF's Y up) or "z" (no turn).
    ``extras`` are stored on the glTF scene.  See the module docstring for the conventions.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".glb", ".gltf"):
        raise ConfigError(f"{path}: glTF output must end in .glb or .gltf")
    if instancing not in ("ext", "nodes"):
        raise ConfigError(f"instancing must be 'ext' or 'nodes', got {instancing!r}")
    if up not in ("y", "z"):
        raise ConfigError(f"up must be 'y' or 'z', got {up!r}")
    b = _Builder()
    report = ExportReport(path=path, bytes=0)
    root_children: list = []
    scene_roots: list = []
    root = b.node(name="piste", rotation=list(Y_UP_ROOT_ROTATION) if up == "y" else None)
    if terrain is not None:
        _add_terrain(b, terrain, root_children, report)
    for c in characters:
        _add_character(b, c, root_children, scene_roots, report)
    if objects is not None and len(objects.kind):
        _add_objects(b, objects, instancing, root_children, report)
    _add_lights(b, list(lights), root_children, report, float(white))
    _add_cameras(b, list(cameras), root_children, report)
    b.g.nodes[root].children = root_children or None
    b.g.scenes = [b.G.Scene(name="piste", nodes=[root] + scene_roots, extras=extras or {})]
    b.g.scene = 0
    if b.used:
        b.g.extensionsUsed = sorted(b.used)
    for name in ("bufferViews", "accessors", "meshes", "materials", "textures", "images", "samplers", "skins",
                 "animations", "cameras"):
        if not getattr(b.g, name):
            setattr(b.g, name, [])
    pad = (-len(b.blob)) % 4
    b.blob.extend(b"\0" * pad)
    blob = bytes(b.blob)
    if suffix == ".glb":
        b.g.buffers = [b.G.Buffer(byteLength=len(blob))] if blob else []
        data = _glb(_json(b.g).encode(), blob)
        write_bytes_atomic(path, data)
        report.bytes = len(data)
        report.files = [path]
    else:
        binp = path.with_suffix(".bin")
        b.g.buffers = [b.G.Buffer(byteLength=len(blob), uri=binp.name)] if blob else []
        text = (_json(b.g) + "\n").encode()
        with atomic_path(path) as tmp:  # the JSON is renamed into place only after the .bin
            tmp.write_bytes(text)
            if blob:
                write_bytes_atomic(binp, blob)
        report.bytes = len(text) + len(blob)
        report.files = [path] + ([binp] if blob else [])
    return report


def _glb(js: bytes, blob: bytes) -> bytes:
    """A GLB container: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    import struct

    js = js + b" " * ((-len(js)) % 4)
    out = [struct.pack("<II", len(js), 0x4E4F534A), js]
    if blob:
        out += [struct.pack("<II", len(blob), 0x004E4942), blob]
    body = b"".join(out)
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _clean(x: Any, key: str | None = None) -> Any:
    """Drop None values, empty lists and empty ``extras`` (glTF forbids empty arrays)."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            v = _clean(v, k)
            if v is None or (isinstance(v, list) and not v) or (k in ("extras", "extensions") and v == {}):
                continue
            out[k] = v
        return out
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return x


def _asdict(x: Any) -> Any:
    """pygltflib's dataclasses as plain JSON values (their field names are the glTF keys); much
    faster than pygltflib's dataclasses-json ``to_json``."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: _asdict(getattr(x, f.name)) for f in dataclasses.fields(x)}
    if isinstance(x, dict):
        return {k: _asdict(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_asdict(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if hasattr(x, "__dict__") and not isinstance(x, (str, bytes, int, float, bool)):  # pygltflib.Attributes
        return {k: _asdict(v) for k, v in vars(x).items() if not k.startswith("_")}
    return x


def _json(g: Any) -> str:
    d = _clean(_asdict(g))
    return json.dumps(d, separators=(",", ":"), sort_keys=True, allow_nan=False)
