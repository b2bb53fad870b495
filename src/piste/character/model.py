"""Character data: Skeleton, Pose, Track, Clip, SkinnedMesh, Model.

Conventions (shared by the whole character package)
---------------------------------------------------
- Quaternions are ``(x, y, z, w)`` (glTF order), float64.
- Matrices are column-vector 4x4: ``p_world = M @ [x, y, z, 1]``.
- ``Skeleton.inverse_bind[i]`` maps mesh/bind space to bone ``i``'s space, so
  ``skin_matrices(pose) = world_matrices(pose) @ inverse_bind`` maps bind-space vertices to the
  posed world; at the bind pose these are identities.
- Bones are ordered so that parents come before children (``parents[i] < i``).

Clip sampling
-------------
``Clip.sample(t)`` clamps ``t`` to ``[0, duration]`` by default; ``loop=True`` wraps it modulo
the duration. Bones without a track keep the target skeleton's rest values.

Animation sharing (retargeting) rule
------------------------------------
A clip plays on any skeleton; tracks are matched to bones **by name**. With
``retarget="scaled"`` (the default when the target is not the clip's own skeleton) rotations and
scales come from the clip unchanged and each bone's translation is the clip's translation scaled
by ``|target rest translation| / |source rest translation|`` of that bone (the ratio of rest bone
lengths; 1 when the source bone has zero length or the source skeleton is unknown). So a skeleton
that is the source scaled by ``k`` plays the clip with every joint position scaled by ``k``.
``retarget="relative"`` applies the clip's change from the source rest pose onto the target's
rest pose instead (``r = r_target_rest * r_source_rest^-1 * r_clip``,
``t = t_target_rest + ratio * (t_clip - t_source_rest)``, ``s = s_target_rest * s_clip /
s_source_rest``): use it when the two skeletons have different rest (bind) orientations.
``retarget="none"`` copies clip values verbatim.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.character import animation as _anim
from piste.character.coverage import check_coverage
from piste.character.morph import vertex_normals
from piste.character.pose import Pose
from piste.character.skeleton import depth_levels, topological_order, world_from_local
from piste.errors import ValidationError
from piste.transforms import compose_trs, invert_affine, quat_normalize

__all__ = ["Skeleton", "Pose", "Track", "Clip", "SkinnedMesh", "Model", "INTERPOLATIONS"]

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Skeleton(DataMethods):
    """A bone hierarchy with its rest (node) pose and inverse bind matrices.

    Attributes
    ----------
    names : list[str] (b,)            unique bone names
    parents : (b,) int32              parent index, -1 for roots, ``parents[i] < i``
    rest_translation : (b, 3) float64
    rest_rotation : (b, 4) float64    xyzw
    rest_scale : (b, 3) float64
    inverse_bind : (b, 4, 4) float64  mesh/bind space -> bone space
    node_index : (b,) int64           glTF node of each bone (-1 if none)
    is_joint : (b,) bool              bone is a joint of a glTF skin (else an ancestor or a rigid
                                      mesh node; its inverse_bind is the inverse of its rest world)
    """

    names: list
    parents: np.ndarray
    rest_translation: np.ndarray
    rest_rotation: np.ndarray
    rest_scale: np.ndarray
    inverse_bind: np.ndarray
    node_index: np.ndarray | None = None
    is_joint: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.names = [str(n) for n in self.names]
        b = len(self.names)
        self.parents = np.asarray(self.parents, dtype=np.int32).reshape(b)
        self.rest_translation = np.asarray(self.rest_translation, dtype=np.float64).reshape(b, 3)
        self.rest_rotation = quat_normalize(np.asarray(self.rest_rotation, dtype=np.float64).reshape(b, 4))
        self.rest_scale = np.asarray(self.rest_scale, dtype=np.float64).reshape(b, 3)
        self.inverse_bind = np.asarray(self.inverse_bind, dtype=np.float64).reshape(b, 4, 4)
        self.node_index = (np.full(b, -1, np.int64) if self.node_index is None
                           else np.asarray(self.node_index, dtype=np.int64).reshape(b))
        self.is_joint = (np.ones(b, bool) if self.is_joint is None
                         else np.asarray(self.is_joint, dtype=bool).reshape(b))
        if len(set(self.names)) != b:
            raise ValidationError("Skeleton bone names must be unique")
        idx = np.arange(b)
        if np.any(self.parents >= idx) or np.any(self.parents < -1):
            raise ValidationError("Skeleton parents must come before children (parents[i] < i, -1 = root); "
                                  "use Skeleton.ordered(...) to reorder")
        self._levels = depth_levels(self.parents)
        self._index = {n: i for i, n in enumerate(self.names)}

    # ------------------------------------------------------------------ construction
    @classmethod
    def ordered(cls, names: Sequence[str], parents: npt.ArrayLike, rest_translation: npt.ArrayLike,
                rest_rotation: npt.ArrayLike, rest_scale: npt.ArrayLike, inverse_bind: npt.ArrayLike,
                node_index: npt.ArrayLike | None = None, is_joint: npt.ArrayLike | None = None) -> tuple[Skeleton, np.ndarray]:
        """Build a skeleton from bones in any order; returns ``(skeleton, order)`` where
        ``order (b,) int64`` maps new bone index -> old index (``new = old[order]``)."""
        par = np.asarray(parents, dtype=np.int64)
        order = topological_order(par)
        inv = np.empty_like(order)
        inv[order] = np.arange(order.size)
        new_par = np.where(par[order] >= 0, inv[np.maximum(par[order], 0)], -1)

        def take(a: npt.ArrayLike) -> np.ndarray:
            return np.asarray(a)[order]

        sk = cls([names[i] for i in order], new_par, take(rest_translation), take(rest_rotation),
                 take(rest_scale), take(inverse_bind), None if node_index is None else take(node_index),
                 None if is_joint is None else take(is_joint))
        return sk, order

    # ------------------------------------------------------------------ queries
    @property
    def n_bones(self) -> int:
        return len(self.names)

    def __len__(self) -> int:
        return len(self.names)

    def bone_index(self, name: str) -> int:
        """Index of the bone called ``name``; KeyError if absent."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"no bone named {name!r} in skeleton ({len(self.names)} bones)") from None

    def get(self, name: str, default: int | None = None) -> int | None:
        """Index of the bone called ``name`` or ``default``."""
        return self._index.get(name, default)

    @property
    def levels(self) -> list:
        """Bone indices per depth level (roots first)."""
        return self._levels

    def rest_pose(self) -> Pose:
        """The rest (node) pose as a Pose (copies)."""
        return Pose(self.rest_translation.copy(), self.rest_rotation.copy(), self.rest_scale.copy())

    def bind_pose_world(self) -> np.ndarray:
        """World matrices of the bind pose ``(b, 4, 4)`` = inverse(inverse_bind)."""
        return invert_affine(self.inverse_bind)

    # ------------------------------------------------------------------ matrices
    def local_matrices(self, pose: Pose | None = None) -> np.ndarray:
        """Local TRS matrices ``(b, 4, 4) float64`` of ``pose`` (rest pose if None)."""
        if pose is None:
            pose = self.rest_pose()
        return compose_trs(pose.translation, pose.rotation, pose.scale)

    def world_matrices(self, pose: Pose | None = None) -> np.ndarray:
        """World (model-space) matrices ``(b, 4, 4) float64``, all bones at once, one batched
        matmul per depth level."""
        return world_from_local(self.local_matrices(pose), self.parents, self._levels)

    def skin_matrices(self, pose: Pose | None = None) -> np.ndarray:
        """Skinning matrices ``(b, 4, 4) float64`` = ``world_matrices(pose) @ inverse_bind``:
        bind-space vertex -> posed world."""
        return self.world_matrices(pose) @ self.inverse_bind


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Track(DataMethods):
    """One animation channel.

    ``times (n,) float64`` strictly increasing key times in seconds; ``values (n, c) float64``
    key values (c = 3 translation/scale, 4 rotation xyzw, k morph weights);
    ``interpolation`` one of LINEAR, STEP, CUBICSPLINE; for CUBICSPLINE ``in_tangents`` and
    ``out_tangents (n, c)`` (glTF's a_k and b_k, per second) are required.
    """

    times: np.ndarray
    values: np.ndarray
    interpolation: str = "LINEAR"
    in_tangents: np.ndarray | None = None
    out_tangents: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.values = np.asarray(self.values, dtype=np.float64).reshape(self.times.shape[0], -1)
        if self.interpolation not in INTERPOLATIONS:
            raise ValidationError(f"interpolation must be one of {INTERPOLATIONS}, got {self.interpolation!r}")
        if self.interpolation == "CUBICSPLINE":
            if self.in_tangents is None or self.out_tangents is None:
                raise ValidationError("CUBICSPLINE track needs in_tangents and out_tangents")
            self.in_tangents = np.asarray(self.in_tangents, dtype=np.float64).reshape(self.values.shape)
            self.out_tangents = np.asarray(self.out_tangents, dtype=np.float64).reshape(self.values.shape)

    @property
    def n_keys(self) -> int:
        return self.times.shape[0]

    @property
    def nbytes(self) -> int:
        """Bytes as stored in glTF (float32 times + values (+ tangents))."""
        n = self.times.size + self.values.size
        if self.interpolation == "CUBICSPLINE":
            assert self.in_tangents is not None and self.out_tangents is not None  # __post_init__ requires them
            n += self.in_tangents.size + self.out_tangents.size
        return 4 * n

    def sample(self, t: float, rotation: bool = False) -> np.ndarray:
        """Value ``(c,)`` at time ``t`` (clamped to the key range); quaternion slerp if ``rotation``."""
        return _anim.sample_track(self, t, rotation=rotation)


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Clip(DataMethods):
    """An animation: tracks by bone name and morph-weight tracks by mesh.

    Attributes
    ----------
    name : str
    duration : float                              seconds (max key time over all tracks)
    tracks : dict[str, dict[str, Track]]          bone name -> {"translation"|"rotation"|"scale": Track}
    weight_tracks : dict[str, Track]              glTF mesh name -> Track with values (n, k)
    skeleton : Skeleton | None                    the skeleton the clip was made for (source of the
                                                  retarget rule's rest values)
    weight_track_mesh_index : dict[int, str]      glTF mesh index -> key in weight_tracks
    """

    name: str
    duration: float
    tracks: dict = field(default_factory=dict)
    weight_tracks: dict = field(default_factory=dict)
    skeleton: Skeleton | None = None
    weight_track_mesh_index: dict = field(default_factory=dict)

    @property
    def nbytes(self) -> int:
        """Bytes of the clip as glTF stores it: float32 values (plus tangents for CUBICSPLINE) and
        each distinct key-time array once (exporters share input accessors between channels)."""
        n = 0
        times = {}
        for tr in [tr for bt in self.tracks.values() for tr in bt.values()] + list(self.weight_tracks.values()):
            n += 4 * tr.values.size * (3 if tr.interpolation == "CUBICSPLINE" else 1)
            times[tr.times.tobytes()] = tr.times.size
        return n + 4 * sum(times.values())

    @property
    def bones(self) -> list:
        """Names of the animated bones."""
        return list(self.tracks)

    def sample(self, t: float, skeleton: Skeleton | None = None, loop: bool = False,
               retarget: str | None = None) -> Pose:
        """Pose of ``skeleton`` (default: the clip's own) at time ``t`` seconds.

        ``t`` is clamped to ``[0, duration]`` unless ``loop`` (then wrapped). Bones without tracks
        keep ``skeleton``'s rest values. ``retarget``: "scaled" (default for a foreign skeleton),
        "relative" or "none"; see the module docstring.
        """
        sk = skeleton if skeleton is not None else self.skeleton
        if sk is None:
            raise ValidationError(f"clip {self.name!r} has no skeleton: pass one to sample()")
        if retarget is None:
            retarget = "none" if sk is self.skeleton else "scaled"
        if sk is not self.skeleton:
            check_coverage(self, sk)  # warns naming the unmatched bones (< half driven)
        t = _anim.clip_time(t, self.duration, loop)
        return _anim.sample_pose(self, t, sk, self.skeleton, retarget)

    def sample_weights(self, t: float, mesh: str | int | SkinnedMesh, loop: bool = False,
                       default: npt.ArrayLike | None = None) -> np.ndarray:
        """Morph weights ``(k,) float64`` of ``mesh`` (glTF mesh name, SkinnedMesh name / object,
        or glTF mesh index) at time ``t``. If the clip does not animate that mesh, returns
        ``default`` (a SkinnedMesh's ``morph_default_weights`` when a SkinnedMesh is given) or
        raises KeyError."""
        key = None
        if isinstance(mesh, SkinnedMesh):
            if default is None:
                default = mesh.morph_default_weights
            for cand in (mesh.group, mesh.name):
                if cand in self.weight_tracks:
                    key = cand
                    break
        elif isinstance(mesh, (int, np.integer)):
            key = self.weight_track_mesh_index.get(int(mesh))
        else:
            key = mesh if mesh in self.weight_tracks else str(mesh).split("/")[0]
        if key is None or key not in self.weight_tracks:
            if default is not None:
                return np.asarray(default, dtype=np.float64).copy()
            raise KeyError(f"clip {self.name!r} has no morph weight track for {mesh!r}")
        t = _anim.clip_time(t, self.duration, loop)
        return _anim.sample_track(self.weight_tracks[key], t)


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class SkinnedMesh(DataMethods):
    """A triangle mesh with optional skin and morph targets (also used for unskinned meshes).

    Attributes
    ----------
    name : str
    positions : (v, 3) float32        bind/mesh space (unskinned meshes: world space at rest)
    normals : (v, 3) float32          unit
    uv : (v, 2) float32
    indices : (t, 3) uint32
    joints : (v, 4) uint16            indices into the model's Skeleton
    weights : (v, 4) float32          rows sum to 1 (zeros allowed)
    morph_positions : (k, v, 3) float32   position deltas
    morph_normals : (k, v, 3) float32     normal deltas
    morph_names : list[str] (k,)
    morph_default_weights : (k,) float32
    texture : (h, w, 4) uint8 or None  base-colour texture (RGBA)
    base_color : (4,) float32          base-colour factor (linear RGBA)
    skinned : bool                     joints/weights are meaningful (False: no skeleton)
    group : str                        glTF mesh name this primitive came from
    material : piste.formats.gltf.material.MaterialInfo or None  the glTF material (alpha mode,
                                       double-sided, UV transform (already applied to ``uv``), emissive, unlit)
    """

    name: str
    positions: np.ndarray
    indices: np.ndarray
    # None (the default) for these makes __post_init__ fill them, so after construction each is an
    # array: typed as the array it always is once built (the None default is the constructor's)
    normals: np.ndarray = None  # type: ignore[assignment]
    uv: np.ndarray = None  # type: ignore[assignment]
    joints: np.ndarray = None  # type: ignore[assignment]
    weights: np.ndarray = None  # type: ignore[assignment]
    morph_positions: np.ndarray = None  # type: ignore[assignment]
    morph_normals: np.ndarray = None  # type: ignore[assignment]
    morph_names: list[str] = field(default_factory=list)
    morph_default_weights: np.ndarray = None  # type: ignore[assignment]
    texture: np.ndarray | None = None
    base_color: np.ndarray = None  # type: ignore[assignment]
    skinned: bool = False
    group: str = ""
    material: object = None

    def __post_init__(self) -> None:
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        v = self.positions.shape[0]
        self.indices = np.ascontiguousarray(self.indices, dtype=np.uint32).reshape(-1, 3)
        if self.normals is None:
            self.normals = vertex_normals(self.positions, self.indices)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(v, 3)
        self.uv = np.zeros((v, 2), np.float32) if self.uv is None else np.ascontiguousarray(self.uv, np.float32).reshape(v, 2)
        if self.joints is None:
            self.joints = np.zeros((v, 4), np.uint16)
        self.joints = np.ascontiguousarray(self.joints, dtype=np.uint16).reshape(v, 4)
        if self.weights is None:
            self.weights = np.zeros((v, 4), np.float32)
            self.weights[:, 0] = 1.0
        self.weights = np.ascontiguousarray(self.weights, dtype=np.float32).reshape(v, 4)
        if self.morph_positions is None:
            self.morph_positions = np.zeros((0, v, 3), np.float32)
        self.morph_positions = np.ascontiguousarray(self.morph_positions, dtype=np.float32).reshape(-1, v, 3)
        k = self.morph_positions.shape[0]
        if self.morph_normals is None:
            self.morph_normals = np.zeros((k, v, 3), np.float32)
        self.morph_normals = np.ascontiguousarray(self.morph_normals, dtype=np.float32).reshape(k, v, 3)
        self.morph_names = list(self.morph_names) + [f"morph{i}" for i in range(len(self.morph_names), k)]
        self.morph_names = self.morph_names[:k]
        if self.morph_default_weights is None:
            self.morph_default_weights = np.zeros(k, np.float32)
        self.morph_default_weights = np.asarray(self.morph_default_weights, dtype=np.float32).reshape(k)
        self.base_color = (np.ones(4, np.float32) if self.base_color is None
                           else np.asarray(self.base_color, dtype=np.float32).reshape(4))
        if not self.group:
            self.group = self.name

    @property
    def n_vertices(self) -> int:
        return self.positions.shape[0]

    @property
    def n_triangles(self) -> int:
        return self.indices.shape[0]

    @property
    def n_morphs(self) -> int:
        return self.morph_positions.shape[0]

    def bounds(self) -> np.ndarray:
        """``(2, 3) float32`` min and max of the positions."""
        if self.n_vertices == 0:
            return np.zeros((2, 3), np.float32)
        return np.stack([self.positions.min(0), self.positions.max(0)])


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Model(DataMethods):
    """A loaded character or scene: skeleton (or None), meshes, clips, lights, cameras.

    ``clips`` is keyed by clip name (unnamed glTF animations become "animation0", ...).
    ``lights`` and ``cameras``: a glTF file's, as piste's own (:mod:`piste.scene_data` lights and
    :class:`~piste.scene_data.Camera`, placed in piste's world by the reader's frame: see
    :mod:`piste.formats.gltf.units`).
    ``meshes``: one SkinnedMesh per glTF primitive (primitives are kept separate because each can
    carry its own material and texture); their ``group`` is the glTF mesh name.
    """

    name: str
    skeleton: Skeleton | None = None
    meshes: list = field(default_factory=list)
    clips: dict = field(default_factory=dict)
    lights: list = field(default_factory=list)
    cameras: list = field(default_factory=list)
    path: str | None = None

    @property
    def morph_targets(self) -> dict:
        """Morph target names per mesh: ``{mesh name: [names]}`` (meshes without morphs omitted)."""
        return {m.name: list(m.morph_names) for m in self.meshes if m.n_morphs}

    @property
    def n_vertices(self) -> int:
        return sum(m.n_vertices for m in self.meshes)

    @property
    def n_triangles(self) -> int:
        return sum(m.n_triangles for m in self.meshes)

    def bounds(self) -> np.ndarray:
        """``(2, 3) float32`` min/max over all mesh positions (bind space)."""
        if not self.meshes:
            return np.zeros((2, 3), np.float32)
        b = np.stack([m.bounds() for m in self.meshes if m.n_vertices] or [np.zeros((2, 3), np.float32)])
        return np.stack([b[:, 0].min(0), b[:, 1].max(0)])

    def size(self) -> float:
        """Diagonal of the bounding box (model units)."""
        b = self.bounds()
        return float(np.linalg.norm(b[1] - b[0]))
