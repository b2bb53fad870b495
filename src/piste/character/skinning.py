"""Skinning, three ways: exact linear blend skinning, SSX post-transform weighting, SSX Tricky
blended (palette) matrices.

All three take *skin matrices* ``(b, 4, 4)`` (``Skeleton.skin_matrices(pose)`` =
``world @ inverse_bind``: bind-space vertex -> posed world, column vectors) and return
``positions (v, 3) float32`` and unit ``normals (v, 3) float32``.

Schemes
-------
``exact`` (the reference)
    Per vertex the blended matrix ``A = sum_i w_i S_i`` (all influences, float64); positions
    ``A @ [p, 1]``; normals by the inverse-transpose of A's 3x3 (computed as its cofactor
    matrix, sign-corrected by ``det``), renormalised. Correct also for scaled bones.
``post_transform`` (SSX)
    A precomputed :class:`PostTransformMesh` stores each vertex in the local space of each of its
    influencing bones, ``(v, k, 3)`` with ``v_Bi = inverse_bind_i @ p``. Per frame the bone
    matrices ``M_Bi = S_i @ inverse(inverse_bind_i)`` (bone -> world) transform each copy and the
    results are weighted: ``v = sum_i w_i (M_Bi v_Bi)``. Normals are **not** weighted: they are
    stored in the dominant (largest-weight) bone's space and transformed by that bone only.
``blended`` (SSX Tricky)
    Weights quantized to ``step`` with at most ``max_bones`` bones (:func:`palette`); per frame
    one weighted matrix per palette entry; each vertex (position and normal) is transformed by
    its single palette matrix's 3x4 (normals by its 3x3, then renormalised). The per-frame
    transform is one sparse matrix-vector product: a constant CSR matrix (built once) maps the
    flattened palette ``(p*12,)`` to all positions and normals, which is the gather + 3x4
    multiply of every vertex in one call (scipy; a numpy gather + einsum fallback exists).

Positions agree exactly between ``exact`` and ``post_transform`` (up to float32 rounding);
``blended`` departs by the weight quantization (CesiumMan: ~1-3 % of its height).

API
---
::

    - ``skin(mesh, bone_matrices, scheme="exact", step=0.25, max_bones=3, inverse_bind=None)``
    - ``skin_exact(mesh, bone_matrices)``
    - ``PostTransformMesh.build(mesh, inverse_bind=None)``, ``.apply(bone_matrices)``
    - ``BlendedMesh.build(mesh, step, max_bones)``, ``.apply(bone_matrices)``,
      ``.apply_many((n, b, 4, 4))`` (several instances in one call), ``.palette_matrices(...)`` and
      ``.skin_palette((n, p, 3, 4))`` (its two halves: the palette, then every vertex by its entry)
    - ``skinning_report(model, steps) -> list[dict]``: palette sizes and errors per weight step
    - ``SCHEMES``
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from piste._data import DataMethods
from piste.character.model import Clip, Model, SkinnedMesh
from piste.character.palette import Palette, _top_weights, palette as _palette
from piste.character.palette import palette as make_palette
from piste.errors import ConfigError, ValidationError

from piste._jit import lazy_njit

_T = TypeVar("_T")


def _blend_py(pal: np.ndarray, run_start: np.ndarray, run_entry: np.ndarray, pos: np.ndarray, nrm: np.ndarray, out_p: np.ndarray, out_n: np.ndarray, normalize: bool,
              cofactor: bool) -> None:
    """Every vertex of every instance by its palette matrix.

    ``pal (n p 12,)`` float32: ``n`` palettes of ``p`` row-major 3x4 matrices, flattened; the
    vertices as runs sharing one entry (run ``r``: vertices ``run_start[r]:run_start[r + 1]``, entry
    ``run_entry[r]``; :func:`_runs`); ``pos/nrm (3 v,)`` float32 (``(v, 3)`` flattened) ->
    ``out_p/out_n (3 n v,)`` float32 (``(n, v, 3)`` flattened).

    Normals by the entry's 3x3 (``cofactor=False``: the same float32 operations in the same order
    as the sparse product and :func:`normalize_rows`, so the same bits) or by its cofactor matrix
    signed by the determinant (``det * inverse-transpose`` up to sign: normals stay perpendicular to
    the skinned surface under a blended, non-rigid 3x3), renormalised when ``normalize``.

    Laid out for SIMD: each run's 12 (+ 9) matrix floats held in registers, a straight loop over
    its vertices, positions and normals computed together, each output written once.  Flat arrays
    indexed by unsigned integers (numba then emits no negative-index wrap-around, so LLVM can tell
    the runs' accesses apart and vectorises the loop: 16 vertices an AVX-512 step)."""
    one = np.float32(1.0)
    zero = np.float32(0.0)
    three = np.uint64(3)
    n = out_p.shape[0] // pos.shape[0] if pos.shape[0] else 0  # instances
    pal_floats = np.uint64(pal.shape[0] // n) if n else np.uint64(0)  # 12 p
    for i in range(n):
        pb = np.uint64(i) * pal_floats
        ob = np.uint64(i) * np.uint64(pos.shape[0])
        for r in range(run_entry.shape[0]):
            k = pb + np.uint64(run_entry[r]) * np.uint64(12)
            a00, a01, a02, a03 = pal[k], pal[k + np.uint64(1)], pal[k + np.uint64(2)], pal[k + np.uint64(3)]
            a10, a11, a12, a13 = pal[k + np.uint64(4)], pal[k + np.uint64(5)], pal[k + np.uint64(6)], pal[k + np.uint64(7)]
            a20, a21, a22, a23 = pal[k + np.uint64(8)], pal[k + np.uint64(9)], pal[k + np.uint64(10)], pal[k + np.uint64(11)]
            if cofactor:
                c00 = a11 * a22 - a12 * a21
                c01 = a12 * a20 - a10 * a22
                c02 = a10 * a21 - a11 * a20
                sg = -one if a00 * c00 + a01 * c01 + a02 * c02 < zero else one
                n00, n01, n02 = sg * c00, sg * c01, sg * c02
                n10 = sg * (a02 * a21 - a01 * a22)
                n11 = sg * (a00 * a22 - a02 * a20)
                n12 = sg * (a01 * a20 - a00 * a21)
                n20 = sg * (a01 * a12 - a02 * a11)
                n21 = sg * (a02 * a10 - a00 * a12)
                n22 = sg * (a00 * a11 - a01 * a10)
            else:
                n00, n01, n02, n10, n11, n12, n20, n21, n22 = a00, a01, a02, a10, a11, a12, a20, a21, a22
            for v in range(np.uint64(run_start[r]), np.uint64(run_start[r + 1])):
                q = v * three
                x, y, z = pos[q], pos[q + np.uint64(1)], pos[q + np.uint64(2)]
                a, b, c = nrm[q], nrm[q + np.uint64(1)], nrm[q + np.uint64(2)]
                o = ob + q
                out_p[o] = a00 * x + a01 * y + a02 * z + a03
                out_p[o + np.uint64(1)] = a10 * x + a11 * y + a12 * z + a13
                out_p[o + np.uint64(2)] = a20 * x + a21 * y + a22 * z + a23
                nx = n00 * a + n01 * b + n02 * c
                ny = n10 * a + n11 * b + n12 * c
                nz = n20 * a + n21 * b + n22 * c
                if normalize:
                    length = np.sqrt(nx * nx + ny * ny + nz * nz)
                    length = one if length == zero else length
                    inv = one / length
                    nx, ny, nz = nx * inv, ny * inv, nz * inv
                out_n[o] = nx
                out_n[o + np.uint64(1)] = ny
                out_n[o + np.uint64(2)] = nz


def _runs(index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs of equal entries in ``index (v,)``: ``run_start (r + 1,) int64`` (ends included) and
    ``run_entry (r,) int64`` (any vertex order works; a mesh sorted by entry has one run per entry)."""
    index = np.asarray(index, dtype=np.int64)
    start = np.flatnonzero(np.r_[True, index[1:] != index[:-1]]) if len(index) else np.zeros(0, np.int64)
    return np.r_[start, len(index)].astype(np.int64), index[start].astype(np.int64)


def _ex_blend() -> tuple[Any, ...]:
    return (np.zeros(12, np.float32), np.array([0, 1], np.int64), np.zeros(1, np.int64), np.zeros(3, np.float32),
            np.zeros(3, np.float32), np.zeros(3, np.float32), np.zeros(3, np.float32), True, False)


_blend_nb = lazy_njit(_blend_py, _ex_blend)  # optional compiled kernel (the 'fast' extra); scipy/numpy is the reference


def _compiled(use_numba: bool | None) -> bool:
    """Use the compiled kernel: forced (True), never (False), or when numba has loaded (None)."""
    return _blend_nb is not None and (use_numba or (use_numba is None and _blend_nb.ready()))

__all__ = ["skin", "skin_exact", "PostTransformMesh", "BlendedMesh", "SCHEMES", "normalize_rows", "skinning_report"]

SCHEMES = ("exact", "post_transform", "blended")


def normalize_rows(n: np.ndarray) -> np.ndarray:
    """Normalise the rows of ``n (v, 3)`` in place (zero rows stay zero); returns ``n``."""
    s = n * n
    length = s[:, 0] + s[:, 1] + s[:, 2]
    np.sqrt(length, out=length)
    length[length == 0] = 1.0
    np.divide(1.0, length, out=length)
    n *= length[:, None]
    return n


def _check_matrices(bone_matrices: ArrayLike, mesh: SkinnedMesh) -> np.ndarray:
    m = np.asarray(bone_matrices)
    if m.ndim != 3 or m.shape[1:] not in ((4, 4), (3, 4)):
        raise ValidationError(f"bone matrices must be (b, 4, 4), got shape {m.shape}")
    if mesh.joints.size and int(mesh.joints.max()) >= m.shape[0]:
        # only influences with weight > 0 must be in range
        used = mesh.weights > 0
        if used.any() and int(mesh.joints[used].max()) >= m.shape[0]:
            raise ValidationError(f"mesh {getattr(mesh, 'name', '')!r} uses bone {int(mesh.joints[used].max())} "
                                  f"but only {m.shape[0]} bone matrices were given")
    return m


def _cofactor3(a: np.ndarray) -> np.ndarray:
    """Cofactor matrices ``(..., 3, 3)`` (= det * inverse-transpose) of ``a (..., 3, 3)``."""
    c0, c1, c2 = a[..., :, 0], a[..., :, 1], a[..., :, 2]
    return np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=-1)


def skin_exact(mesh: SkinnedMesh, bone_matrices: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Reference linear blend skinning (float64 inside, all influences).

    Returns ``positions (v, 3) float32`` and unit ``normals (v, 3) float32`` (inverse-transpose
    of each vertex's blended 3x3, renormalised).
    """
    m = _check_matrices(bone_matrices, mesh).astype(np.float64)[:, :3, :]
    j = mesh.joints.astype(np.intp)
    w = mesh.weights.astype(np.float64)
    total = w.sum(1, keepdims=True)
    total[total == 0] = 1.0
    w = w / total
    safe_j = np.where(w > 0, j, 0)
    a = np.einsum("vk,vkij->vij", w, m[safe_j])  # (v, 3, 4)
    p = mesh.positions.astype(np.float64)
    pos = np.einsum("vij,vj->vi", a[:, :, :3], p) + a[:, :, 3]
    cof = _cofactor3(a[:, :, :3])
    det = np.einsum("vi,vi->v", a[:, :, 0], np.cross(a[:, :, 1], a[:, :, 2]))
    nrm = np.einsum("vij,vj->vi", cof, mesh.normals.astype(np.float64)) * np.sign(det + (det == 0))[:, None]
    nrm = normalize_rows(nrm)
    return pos.astype(np.float32), nrm.astype(np.float32)


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class PostTransformMesh(DataMethods):
    """SSX post-transform weighting data, precomputed once per mesh.

    Attributes
    ----------
    bone_positions : (v, k, 3) float32   the vertex in each influencing bone's local space
    bone_normals : (v, 3) float32        the normal in the dominant bone's space
    bones : (v, k) int32                 influencing bones, by descending weight (slot 0 dominant)
    weights : (v, k) float32             their weights (renormalised, unused slots 0)
    bind_world : (b, 4, 4) float64       ``inverse(inverse_bind)``: converts skin matrices to bone
                                         matrices (bone -> world)
    """

    bone_positions: np.ndarray
    bone_normals: np.ndarray
    bones: np.ndarray
    weights: np.ndarray
    bind_world: np.ndarray

    @classmethod
    def build(cls, mesh: SkinnedMesh, inverse_bind: ArrayLike | None = None, max_bones: int = 4) -> "PostTransformMesh":
        """Store ``mesh``'s vertices in bone space.

        ``inverse_bind (b, 4, 4)``: the skeleton's inverse bind matrices (bind -> bone space).
        None uses identities for every bone used: "bone space" is then the bind space and the
        arithmetic (transform by each bone, then weight; dominant-bone normals) is unchanged.
        """
        bones, w = _top_weights(mesh.joints, mesh.weights, max_bones)
        nb = int(bones.max()) + 1 if bones.size else 1
        if inverse_bind is None:
            ib = np.broadcast_to(np.eye(4), (nb, 4, 4)).copy()
        else:
            ib = np.asarray(inverse_bind, dtype=np.float64)
            if ib.ndim != 3 or ib.shape[1:] != (4, 4):
                raise ValidationError(f"inverse_bind must be (b, 4, 4), got {ib.shape}")
            if ib.shape[0] < nb:
                raise ValidationError(f"mesh uses bone {nb - 1} but inverse_bind has {ib.shape[0]} bones")
        bones = np.where(w > 0, bones, bones[:, :1]).astype(np.int32)
        p = mesh.positions.astype(np.float64)
        mats = ib[bones]  # (v, k, 4, 4)
        bp = np.einsum("vkij,vj->vki", mats[..., :3, :3], p) + mats[..., :3, 3]
        dom = ib[bones[:, 0], :3, :3]
        cof = _cofactor3(dom)
        bn = normalize_rows(np.einsum("vij,vj->vi", cof, mesh.normals.astype(np.float64)))
        det = np.linalg.det(ib[:, :3, :3])
        bind_world = np.linalg.inv(ib) if np.all(np.abs(det) > 1e-12) else np.linalg.pinv(ib)
        return cls(bp.astype(np.float32), bn.astype(np.float32), bones, w.astype(np.float32), bind_world)

    def bone_matrices(self, skin_matrices: ArrayLike) -> np.ndarray:
        """Bone -> world matrices ``(b, 3, 4) float32`` from skin matrices ``(b, 4, 4)``."""
        s = np.asarray(skin_matrices, dtype=np.float64)
        b = self.bind_world.shape[0]
        if s.ndim != 3 or s.shape[1:] not in ((4, 4), (3, 4)) or s.shape[0] < b:
            raise ValidationError(f"expected skin matrices (b >= {b}, 4, 4), got shape {s.shape}")
        return np.matmul(s[:b, :3, :], self.bind_world).astype(np.float32)

    def apply(self, skin_matrices: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Skin one frame: ``positions (v, 3) float32``, ``normals (v, 3) float32``."""
        mb = self.bone_matrices(skin_matrices)
        g = mb[self.bones]  # (v, k, 3, 4)
        pos = np.einsum("vkij,vkj->vki", g[..., :3], self.bone_positions)
        pos += g[..., 3]
        pos = np.einsum("vk,vki->vi", self.weights, pos)
        dom = g[:, 0, :, :3]
        nrm = normalize_rows(np.einsum("vij,vj->vi", dom, self.bone_normals))
        return pos.astype(np.float32, copy=False), nrm


class BlendedMesh:
    """SSX Tricky blended-matrix skinning of one mesh, precomputed once.

    Attributes
    ----------
    palette : Palette            quantized weight combinations and each vertex's entry
    n_vertices : int
    """

    def __init__(self, palette: Palette, positions: ArrayLike, normals: ArrayLike, use_sparse: bool | None = None) -> None:
        self.palette = palette
        p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
        n = np.ascontiguousarray(normals, dtype=np.float32).reshape(-1, 3)
        v = p.shape[0]
        if palette.index.shape[0] != v or n.shape[0] != v:
            raise ValidationError(f"palette has {palette.index.shape[0]} vertices, positions {v}, normals {n.shape[0]}")
        self.n_vertices = v
        self._pos3, self._nrm3 = p, n  # (v, 3) float32 each, for the compiled kernel
        self._index = np.ascontiguousarray(palette.index, dtype=np.int64)
        self._run_start, self._run_entry = _runs(self._index)  # the compiled kernel's vertex runs
        self._matrices = np.empty((palette.size, 3, 4), np.float32)
        # palette generation as one small GEMM: (p, b) weights @ (b, 12) bone matrices
        nb = int(palette.bones.max()) + 1 if palette.size else 1
        self._weights = np.zeros((palette.size, nb), np.float32)
        rows = np.repeat(np.arange(palette.size), palette.bones.shape[1])
        np.add.at(self._weights, (rows, palette.bones.reshape(-1)), palette.weights.reshape(-1))
        self._sparse = None
        self._use_sparse = use_sparse
        if use_sparse or (use_sparse is None and _blend_nb is None):  # with numba: built if ever needed
            self._make_sparse()

    def _make_sparse(self) -> None:
        use_sparse, palette = self._use_sparse, self.palette
        p, n = self._pos3, self._nrm3
        if self._sparse is None and (use_sparse is None or use_sparse):
            try:
                import scipy.sparse as sp
            except ImportError:  # pragma: no cover - scipy is in the dev environment
                if use_sparse:
                    raise ConfigError("use_sparse=True needs scipy") from None
            else:
                self._sparse = self._build_sparse(sp, palette.index, p, n)

    @staticmethod
    def _build_sparse(sp: Any, index: np.ndarray, p: np.ndarray, n: np.ndarray) -> Any:
        """CSR ``(6v, 12p) float32``: rows ``3*i + r`` give position coordinate r of vertex i,
        rows ``3v + 3*i + r`` the (unnormalised) normal; columns index the flattened palette."""
        v = p.shape[0]
        psize = int(index.max()) + 1 if v else 0
        base = index.astype(np.int64)[:, None, None] * 12 + np.arange(3)[None, :, None] * 4
        cols_p = (base + np.arange(4)[None, None, :]).reshape(-1)
        cols_n = (base + np.arange(3)[None, None, :]).reshape(-1)
        data_p = np.broadcast_to(np.concatenate([p, np.ones((v, 1), np.float32)], 1)[:, None, :], (v, 3, 4)).reshape(-1)
        data_n = np.broadcast_to(n[:, None, :], (v, 3, 3)).reshape(-1)
        indptr = np.concatenate([np.arange(0, 12 * v, 4), 12 * v + np.arange(0, 9 * v + 1, 3)])
        itype = np.int32 if 21 * v < 2**31 and 12 * psize < 2**31 else np.int64
        return sp.csr_matrix((np.concatenate([data_p, data_n]).astype(np.float32),
                              np.concatenate([cols_p, cols_n]).astype(itype), indptr.astype(itype)),
                             shape=(6 * v, 12 * max(psize, 1)))

    @classmethod
    def build(cls, mesh: SkinnedMesh, step: float = 0.25, max_bones: int = 3, use_sparse: bool | None = None) -> "BlendedMesh":
        """Quantize ``mesh``'s weights into a palette and precompute the per-vertex mapping."""
        return cls(_palette(mesh, step, max_bones), mesh.positions, mesh.normals, use_sparse)

    def palette_matrices(self, skin_matrices: ArrayLike) -> np.ndarray:
        """This frame's palette ``(p, 3, 4) float32`` (``(n, p, 3, 4)`` for ``(n, b, 4, 4)`` input):
        ``sum_i w_i * skin_matrices[bone_i]`` for every entry, as one ``(p, b) @ (b, 12)`` GEMM."""
        m = np.asarray(skin_matrices)
        nb = self._weights.shape[1]
        if m.ndim < 3 or m.shape[-2:] not in ((4, 4), (3, 4)) or m.shape[-3] < nb:
            raise ValidationError(f"expected skin matrices (b >= {nb}, 4, 4), got shape {m.shape}")
        m12 = m[..., :nb, :3, :].astype(np.float32).reshape(m.shape[:-3] + (nb, 12))
        return np.matmul(self._weights, m12).reshape(m.shape[:-3] + (self.palette.size, 3, 4))

    def apply_many(self, skin_matrices: ArrayLike, normalize: bool = True, use_numba: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Skin ``n`` instances at once (e.g. six riders in different poses): ``skin_matrices
        (n, b, 4, 4)`` -> ``positions (n, v, 3)``, ``normals (n, v, 3)`` float32. With numba one
        compiled pass over all vertices of all instances (``use_numba=False``: one scipy sparse x
        dense product, the reference).  = :meth:`skin_palette` of :meth:`palette_matrices`."""
        return self.skin_palette(self.palette_matrices(skin_matrices), normalize=normalize, use_numba=use_numba)

    def skin_palette(self, palette_matrices: ArrayLike, normalize: bool = True, use_numba: bool | None = None,
                     inverse_transpose: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The per-vertex half of skinning, given this frame's palette: ``palette_matrices (n, p, 3, 4)``
        (or ``(p, 3, 4)``; float32, e.g. from :meth:`palette_matrices`) -> ``positions (n, v, 3)``,
        ``normals (n, v, 3)`` float32 (``(v, 3)`` each for a ``(p, 3, 4)`` palette).  Each vertex by its
        entry's 3x4; normals by the entry's 3x3 (the talk's scheme) or, with ``inverse_transpose``, by
        its inverse-transpose (as the cofactor matrix signed by the determinant: what exact skinning and
        Panda3D do, perpendicular to the skinned surface where a blended 3x3 is not a rotation);
        renormalised when ``normalize``.  With numba one compiled pass (positions and normals
        together); ``use_numba=False``: numpy (the scipy sparse product for the 3x3 normals: the same
        bits; an einsum of the cofactor matrices otherwise)."""
        pal = np.asarray(palette_matrices)
        single = pal.ndim == 3
        if single:
            pal = pal[None]
        p = self.palette.size
        if pal.ndim != 4 or pal.shape[1:] != (p, 3, 4):
            raise ValidationError(f"expected a palette of ({p}, 3, 4) or (n, {p}, 3, 4) matrices, got shape "
                                  f"{np.shape(palette_matrices)}")
        pos, nrm = self._skin_palette(pal, normalize, use_numba, bool(inverse_transpose))
        return (pos[0], nrm[0]) if single else (pos, nrm)

    def _skin_palette(self, pal: np.ndarray, normalize: bool, use_numba: bool | None, inverse_transpose: bool = False) -> tuple[np.ndarray, np.ndarray]:
        n = pal.shape[0]
        v = self.n_vertices
        pos: np.ndarray
        nrm: np.ndarray
        if _compiled(use_numba):
            pos = np.empty((n, v, 3), np.float32)
            nrm = np.empty((n, v, 3), np.float32)
            _blend_nb(np.ascontiguousarray(pal, dtype=np.float32).reshape(-1), self._run_start, self._run_entry,
                      self._pos3.reshape(-1), self._nrm3.reshape(-1), pos.reshape(-1), nrm.reshape(-1), bool(normalize),
                      inverse_transpose)
            return pos, nrm
        pal = pal.astype(np.float32, copy=False)
        if inverse_transpose:
            a = pal[..., :3]
            cof = _cofactor3(a)  # (n, p, 3, 3) float32
            det = np.einsum("...i,...i->...", a[..., 0], np.cross(a[..., 1], a[..., 2]))
            cof *= np.where(det < 0, np.float32(-1), np.float32(1))[..., None, None]
            g = pal[:, self.palette.index]  # (n, v, 3, 4); below in the compiled kernel's order (the same bits)
            c = cof[:, self.palette.index]  # (n, v, 3, 3)
            x, y, z = (self._pos3[None, :, j, None] for j in range(3))
            a, b, d = (self._nrm3[None, :, j, None] for j in range(3))
            pos = g[..., 0] * x + g[..., 1] * y + g[..., 2] * z + g[..., 3]
            nrm = c[..., 0] * a + c[..., 1] * b + c[..., 2] * d
            if normalize:
                for i in range(n):
                    normalize_rows(nrm[i])
            return pos.astype(np.float32, copy=False), nrm.astype(np.float32, copy=False)
        if use_numba is False or _blend_nb is None:  # the reference (while numba loads: _blend_numpy, the same bits)
            self._make_sparse()
        if self._sparse is not None:
            out = np.ascontiguousarray((self._sparse @ pal.reshape(n, -1).T).T)  # (n, 6v)
            pos = out[:, : 3 * v].reshape(n, v, 3)
            nrm = out[:, 3 * v:].reshape(n, v, 3)
        else:
            pos, nrm = self._blend_numpy(pal[:, self.palette.index])
        if normalize:
            for i in range(n):  # per instance: each nrm[i] is a contiguous (v, 3) view
                normalize_rows(nrm[i])
        return pos, nrm

    def _blend_numpy(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and unnormalised normals ``(..., v, 3) float32`` from each vertex's palette
        matrix ``g (..., v, 3, 4) float32``, in the compiled kernel's float32 order
        (``a00 x + a01 y + a02 z + a03``, left to right: the same bits as :func:`_blend_py` and the
        sparse product).  The path a fresh process takes while numba loads in the background: an
        einsum here summed in another order and moved about a quarter of the coordinates by an ulp, so the
        riders of its first frames differed from the later frames' (issue 23)."""
        x, y, z = (self._pos3[:, j, None] for j in range(3))
        a, b, c = (self._nrm3[:, j, None] for j in range(3))
        pos = g[..., 0] * x + g[..., 1] * y + g[..., 2] * z + g[..., 3]
        nrm = g[..., 0] * a + g[..., 1] * b + g[..., 2] * c
        return pos, nrm

    def apply(self, skin_matrices: ArrayLike, normalize: bool = True, use_numba: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Skin one frame: generate the palette ``(p, 3, 4)`` then transform every vertex by its
        entry. Returns ``positions (v, 3) float32`` and ``normals (v, 3) float32`` (unit if
        ``normalize``)."""
        if _compiled(use_numba):
            pos, nrm = self.apply_many(np.asarray(skin_matrices)[None], normalize=normalize, use_numba=True)
            return pos[0], nrm[0]
        m = self.palette_matrices(skin_matrices)
        v = self.n_vertices
        if use_numba is False or _blend_nb is None:
            self._make_sparse()
        if self._sparse is not None:
            out = self._sparse @ m.reshape(-1)
            pos = out[: 3 * v].reshape(v, 3)
            nrm = out[3 * v:].reshape(v, 3)
        else:
            pos, nrm = self._blend_numpy(m[self.palette.index])
        if normalize:
            normalize_rows(nrm)
        return pos, nrm


# ---------------------------------------------------------------------------------- skin()
_CACHE: dict[tuple[Any, ...], tuple[Any, Any, Any]] = {}


def _cached(mesh: SkinnedMesh, key: tuple[Any, ...], make: Callable[[], _T]) -> _T:
    """Precomputed data for ``mesh`` (weakly keyed by identity, invalidated when its arrays are
    replaced)."""
    stamp = (id(mesh.positions), id(mesh.normals), id(mesh.joints), id(mesh.weights))
    k = (id(mesh),) + key
    hit = _CACHE.get(k)
    if hit is not None and hit[0] == stamp:
        return hit[1]
    obj = make()
    try:
        ref = weakref.ref(mesh, lambda _r, k=k: _CACHE.pop(k, None))  # type: ignore[misc]
    except TypeError:  # not weak-referenceable: do not cache
        return obj
    _CACHE[k] = (stamp, obj, ref)
    return obj


def skin(mesh: SkinnedMesh, bone_matrices: ArrayLike, scheme: str = "exact", step: float = 0.25, max_bones: int = 3,
         inverse_bind: ArrayLike | None = None, normalize: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Skin ``mesh`` with skin matrices ``bone_matrices (b, 4, 4)``.

    Parameters
    ----------
    mesh : SkinnedMesh
        ``positions``, ``normals``, ``joints (v,4)``, ``weights (v,4)``
    bone_matrices : (b, 4, 4)
        ``Skeleton.skin_matrices(pose)``
    scheme : "exact", "post_transform" or "blended"
        see the module docstring
    step, max_bones
        weight quantization of ``blended``
    inverse_bind : (b, 4, 4)
        bone spaces of ``post_transform`` (None: identities)
    normalize : bool
        renormalise ``blended`` normals

    Returns
    -------
    positions (v, 3) float32, normals (v, 3) float32
        The per-mesh precomputation of ``post_transform`` and ``blended`` is cached on the mesh
        object (by identity); use :class:`PostTransformMesh` / :class:`BlendedMesh` directly to
        hold it yourself.
    """
    if scheme == "exact":
        return skin_exact(mesh, bone_matrices)
    m = np.asarray(bone_matrices)  # the precomputed objects check the shape and bone count
    if scheme == "post_transform":
        ib_key = None if inverse_bind is None else np.asarray(inverse_bind).tobytes()
        pt = _cached(mesh, ("post", ib_key), lambda: PostTransformMesh.build(mesh, inverse_bind))
        return pt.apply(m)
    if scheme == "blended":
        bm = _cached(mesh, ("blended", float(step), int(max_bones)),
                     lambda: BlendedMesh.build(mesh, step, max_bones))
        return bm.apply(m, normalize=normalize)
    raise ConfigError(f"skinning scheme must be one of {SCHEMES}, got {scheme!r}")


def skinning_report(model: Model, steps: Sequence[float] = (0.1, 0.2, 0.25), max_bones: int = 3,
                    times: Sequence[float] | np.ndarray | None = None, clip: Clip | None = None) -> list[dict[str, float]]:
    """Blended and post-transform accuracy of a model against exact skinning.

    For each ``step``: palette size (summed over the skinned meshes), max and mean position error
    relative to the posed model's size (largest bounding-box extent, ~ its height), max normal
    error in degrees; plus the post-transform scheme's max position error (relative) and max
    normal error (dominant-bone normals). Errors are taken over ``times`` (default: 5 times
    across ``clip``, the model's first clip, or the rest pose if it has none).

    Returns a list of dicts with keys ``step``, ``palette``, ``pos_max``, ``pos_mean``,
    ``normal_max_deg``, ``post_pos_max``, ``post_normal_max_deg``.
    """
    sk = model.skeleton
    meshes = [m for m in model.meshes if m.skinned]
    if sk is None or not meshes:
        return []
    if clip is None and model.clips:
        clip = next(iter(model.clips.values()))
    if times is None:
        times = np.linspace(0.0, clip.duration, 5) if clip is not None else [0.0]
    poses = [clip.sample(t, loop=True) if clip is not None else sk.rest_pose() for t in times]
    mats = [sk.skin_matrices(p) for p in poses]

    def ang(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = a.astype(np.float64)
        b = b.astype(np.float64)
        return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))

    exact = [[skin_exact(me, m) for me in meshes] for m in mats]
    sizes = [float(np.ptp(np.concatenate([e[0] for e in ex]), axis=0).max()) or 1.0 for ex in exact]
    post_d, post_a = [], []
    for m, ex, size in zip(mats, exact, sizes):
        for me, (pe, ne) in zip(meshes, ex):
            pp, npt = skin(me, m, "post_transform", inverse_bind=sk.inverse_bind)
            post_d.append(np.linalg.norm(pp - pe, axis=1) / size)
            post_a.append(ang(npt, ne))
    rows = []
    for step in steps:
        ds: list[np.ndarray] = []
        a: list[np.ndarray] = []
        for m, ex, size in zip(mats, exact, sizes):
            for me, (pe, ne) in zip(meshes, ex):
                pb, nb = skin(me, m, "blended", step=step, max_bones=max_bones)
                ds.append(np.linalg.norm(pb - pe, axis=1) / size)
                a.append(ang(nb, ne))
        d = np.concatenate(ds)
        rows.append({
            "step": float(step),
            "palette": int(sum(make_palette(me, step, max_bones).size for me in meshes)),
            "pos_max": float(d.max()),
            "pos_mean": float(d.mean()),
            "normal_max_deg": float(np.concatenate(a).max()),
            "post_pos_max": float(np.concatenate(post_d).max()),
            "post_normal_max_deg": float(np.concatenate(post_a).max()),
        })
    return rows
