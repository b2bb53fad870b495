"""Morph targets (blend shapes) and their null-bone alternative.

- ``vertex_normals(positions, indices) -> (v, 3) float32``: area-weighted smooth normals.
- ``blend_morphs(mesh, weights) -> (positions (v,3), normals (v,3))``: base + sum_k w_k delta_k,
  normals renormalised; one GEMV over all targets.
- ``morphs_to_null_bones(mesh, n_bones, max_influences=2) -> NullBoneRig``: the null-bone
  alternative (translation-only bones with per-vertex weights), fitted by clustering + ALS.
- ``morph_report(mesh, rig) -> dict``: bytes, flops, measured time per frame and error of both.
- ``face_weights(names, t, riders) -> (n, k)``: a procedural face (blink, mouth; other targets in turn).
- ``FaceSkin(mesh, palette_index, mode)``: morph targets or null bones added after blended-matrix
  skinning (what the renderer draws: faces that move).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.errors import ValidationError

# ``mesh`` below is a piste.character.model.SkinnedMesh, typed Any: model.py imports this module

__all__ = ["vertex_normals", "blend_morphs", "NullBoneRig", "morphs_to_null_bones", "morph_report", "face_weights",
           "FaceSkin", "FACE_NULL_BONES"]


def vertex_normals(positions: npt.ArrayLike, indices: npt.ArrayLike) -> np.ndarray:
    """Area-weighted vertex normals ``(v, 3) float32`` of a triangle mesh; unused vertices get +Z."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    n = np.zeros_like(p)
    if f.size:
        fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        for c in range(3):
            np.add.at(n, f[:, c], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(ln > 1e-30, n / np.where(ln > 1e-30, ln, 1.0), np.array([0.0, 0.0, 1.0]))
    return out.astype(np.float32)


def _normalize_rows(v: np.ndarray) -> np.ndarray:
    ln = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(ln > 1e-30, v / np.where(ln > 1e-30, ln, 1.0), v)


def blend_morphs(mesh: Any, weights: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Blended ``(positions (v, 3) float32, normals (v, 3) float32)`` of ``mesh`` at ``weights (k,)``.

    ``positions = mesh.positions + sum_k weights[k] * mesh.morph_positions[k]`` and likewise the
    normals, which are then renormalised. Computed as one ``(k,) @ (k, v*3)`` product.
    """
    w = np.asarray(weights, dtype=np.float32).reshape(-1)
    k = mesh.morph_positions.shape[0]
    if w.shape[0] != k:
        raise ValidationError(f"mesh {mesh.name!r} has {k} morph targets, got {w.shape[0]} weights")
    v = mesh.positions.shape[0]
    if k == 0:
        return mesh.positions.copy(), mesh.normals.copy()
    pos = mesh.positions + (w @ mesh.morph_positions.reshape(k, v * 3)).reshape(v, 3)
    nrm = mesh.normals + (w @ mesh.morph_normals.reshape(k, v * 3)).reshape(v, 3)
    return pos.astype(np.float32), _normalize_rows(nrm).astype(np.float32)


# ---------------------------------------------------------------------------------------------- null bones
@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class NullBoneRig(DataMethods):
    """Translation-only ("null") bones approximating a mesh's morph targets.

    A vertex ``v`` listed in ``vertices`` moves by ``sum_i weights[r, i] * t[joints[r, i]]`` where
    the bone translations are ``t = morph_weights @ offsets`` (``(J, 3)`` per frame). Weights are
    in ``[0, 1]`` with row sums ``<= 1``, so in a matrix-palette renderer each null bone is a child
    of the head bone and the remaining weight stays on the head: the skinned result is
    ``H (v + sum_i w_i t_i)``. Normals are not changed by translation-only bones.

    Attributes
    ----------
    mesh_name : str
    vertices : (m,) int32        the vertices any morph target moves
    joints : (m, n) uint16       null-bone index per influence
    weights : (m, n) float32
    offsets : (k, J, 3) float32  translation of each null bone at weight 1 of each target
    """

    mesh_name: str
    vertices: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    offsets: np.ndarray

    @property
    def n_bones(self) -> int:
        return self.offsets.shape[1]

    @property
    def nbytes(self) -> int:
        """Bytes stored: offsets (float32) + per moved vertex index (uint32), joints (uint16) and
        weights (float32)."""
        return int(self.offsets.size * 4 + self.vertices.size * 4 + self.joints.size * 2 + self.weights.size * 4)

    def bone_translations(self, morph_weights: npt.ArrayLike) -> np.ndarray:
        """``(J, 3) float32`` null-bone translations for morph weights ``(k,)``."""
        w = np.asarray(morph_weights, dtype=np.float32).reshape(-1)
        k, J, _ = self.offsets.shape
        return (w @ self.offsets.reshape(k, J * 3)).reshape(J, 3)

    def apply(self, mesh: Any, morph_weights: npt.ArrayLike) -> np.ndarray:
        """Positions ``(v, 3) float32`` of ``mesh`` displaced by the null bones."""
        t = self.bone_translations(morph_weights)
        pos = mesh.positions.copy()
        pos[self.vertices] += np.einsum("mi,mic->mc", self.weights, t[self.joints])
        return pos


def _solve_weights(X: np.ndarray, B: np.ndarray, max_influences: int) -> np.ndarray:
    """Per-vertex nonnegative weights on at most ``max_influences`` bones: ``(m, J)``."""
    m = X.shape[0]
    J = B.shape[0]
    n = min(max_influences, J)
    bn = np.linalg.norm(B, axis=1)
    if n == 1:
        score = (X @ B.T) ** 2 / np.where(bn > 0, bn * bn, np.inf)[None]
    else:  # unconstrained least squares over all bones, keep the largest nonnegative contributions
        full = X @ np.linalg.pinv(B)
        score = np.maximum(full, 0.0) * bn[None]
    sel = np.argsort(-score, axis=1)[:, :n]  # (m, n)
    Bs = B[sel]  # (m, n, c)
    G = np.einsum("mic,mjc->mij", Bs, Bs)
    reg = 1e-9 * np.trace(G, axis1=1, axis2=2)[:, None, None] + 1e-300
    G = G + reg * np.eye(n)[None]
    r = np.einsum("mic,mc->mi", Bs, X)
    w = np.linalg.solve(G, r[..., None])[..., 0]
    w = np.maximum(w, 0.0)
    W = np.zeros((m, J))
    np.put_along_axis(W, sel, w, axis=1)
    return W


def morphs_to_null_bones(mesh: Any, n_bones: int, max_influences: int = 2, iterations: int = 20,
                         seed: int = 0) -> NullBoneRig:
    """Approximate ``mesh``'s morph targets with ``n_bones`` translation-only bones.

    Each moved vertex has a signature ``x_v = (delta_1(v), ..., delta_k(v))`` (3k numbers); the fit
    is the factorization ``X ~= W B`` with ``W (m, J)`` nonnegative vertex weights (at most
    ``max_influences`` per vertex, row sums <= 1) and ``B (J, 3k)`` the bone offsets per target:
    k-means++ clustering of the signatures gives the start, then alternating least squares
    (B by least squares, W by batched small normal equations on each vertex's best bones).
    Deterministic for a given ``seed``.
    """
    from scipy.cluster.vq import kmeans2

    D = np.asarray(mesh.morph_positions, dtype=np.float64)  # (k, v, 3)
    k, v, _ = D.shape
    if k == 0:
        raise ValidationError(f"mesh {mesh.name!r} has no morph targets")
    X_all = D.transpose(1, 0, 2).reshape(v, 3 * k)
    amax = np.abs(X_all).max(axis=1)
    moving = np.flatnonzero(amax > 1e-6 * amax.max()) if amax.size and amax.max() > 0 else np.zeros(0, np.int64)
    X = X_all[moving]
    m = X.shape[0]
    J = int(max(1, min(n_bones, m))) if m else 1
    if m == 0:
        return NullBoneRig(mesh.name, moving.astype(np.int32), np.zeros((0, 1), np.uint16),
                           np.zeros((0, 1), np.float32), np.zeros((k, 1, 3), np.float32))
    rng = np.random.default_rng(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        B, _ = kmeans2(X, J, minit="++", seed=rng)
    B = np.where(np.isfinite(B), B, 0.0)
    best: tuple[float, np.ndarray | None, np.ndarray | None] = (np.inf, None, None)
    for n_inf in sorted({1, int(max_influences)}):  # the 1-influence fit seeds the wider one
        if best[2] is not None:
            B = best[2]
        for _ in range(iterations):
            W = _solve_weights(X, B, n_inf)
            # use each bone's headroom (max weight 1), then keep row sums <= 1
            s = W.max(axis=0)
            s = np.where(s > 0, s, 1.0)
            W = W / s
            B = B * s[:, None]
            rs = W.sum(axis=1, keepdims=True)
            W = np.where(rs > 1, W / np.where(rs > 1, rs, 1), W)
            B = np.linalg.lstsq(W, X, rcond=None)[0]
            res = float(np.sum((X - W @ B) ** 2))
            if res < best[0]:
                best = (res, W, B)
    _, W_best, B_best = best
    if W_best is None or B_best is None:  # no iteration ran (or every residual was NaN)
        raise ValidationError(f"morphs_to_null_bones: no fit of mesh {mesh.name!r} (iterations={iterations})")
    W, B = W_best, B_best
    n = max(1, int(np.count_nonzero(W, axis=1).max()))
    sel = np.argsort(-W, axis=1)[:, :n]
    wsel = np.take_along_axis(W, sel, axis=1)
    offsets = B.reshape(J, k, 3).transpose(1, 0, 2)
    return NullBoneRig(mesh.name, moving.astype(np.int32), sel.astype(np.uint16), wsel.astype(np.float32),
                       offsets.astype(np.float32))


def morph_report(mesh: Any, rig: NullBoneRig, n_samples: int = 64, seed: int = 0,
                 timing_repeats: int = 50) -> dict[str, Any]:
    """Memory, cost and error of blended morph targets vs the null-bone rig for ``mesh``.

    Error is measured on each target alone at weight 1 and on ``n_samples`` random weight vectors
    in ``[0, 1]^k``: ``max_error`` / ``rms_error`` in model units, ``relative_error`` = max error /
    the largest morph displacement, ``normal_error_deg`` = largest angle between blended morph
    normals and the (unchanged) base normals the null bones leave. Bytes: morph deltas dense
    (positions + normals, float32) and sparse (moved vertices only, with uint32 indices); null
    bones per :attr:`NullBoneRig.nbytes`. Cost: flops per frame and measured seconds per frame.
    """
    k, v = mesh.n_morphs, mesh.n_vertices
    rng = np.random.default_rng(seed)
    ws = np.concatenate([np.eye(k), rng.uniform(0, 1, size=(n_samples, k))]).astype(np.float32)
    err_rows: list[np.ndarray] = []
    nerr = 0.0
    for w in ws:
        p_m, n_m = blend_morphs(mesh, w)
        p_b = rig.apply(mesh, w)
        err_rows.append(np.linalg.norm(p_m.astype(np.float64) - p_b, axis=1))
        cosang = np.clip(np.sum(n_m * mesh.normals, axis=1), -1, 1)
        nerr = max(nerr, float(np.degrees(np.arccos(cosang)).max()) if v else 0.0)
    errs = np.stack(err_rows)
    disp = float(np.linalg.norm(mesh.morph_positions, axis=2).max()) if k and v else 0.0
    m = rig.vertices.size
    has_n = bool(np.any(mesh.morph_normals))
    comps = 6 if has_n else 3
    dense = k * v * comps * 4
    sparse = k * m * comps * 4 + m * 4
    J = rig.n_bones
    n_inf = rig.weights.shape[1] if rig.weights.ndim == 2 else 0
    flops_morph = 2 * k * v * comps + (9 * v if has_n else 0)  # GEMV + renormalise
    flops_null = 2 * k * J * 3 + 2 * n_inf * 3 * m
    t0 = time.perf_counter()
    for i in range(timing_repeats):
        blend_morphs(mesh, ws[i % len(ws)])
    t_morph = (time.perf_counter() - t0) / timing_repeats
    t0 = time.perf_counter()
    for i in range(timing_repeats):
        rig.apply(mesh, ws[i % len(ws)])
    t_null = (time.perf_counter() - t0) / timing_repeats
    return dict(mesh=mesh.name, vertices=v, targets=k, moved_vertices=m, null_bones=J,
                bytes_morph_dense=dense, bytes_morph_sparse=sparse, bytes_null_bones=rig.nbytes,
                flops_morph=flops_morph, flops_null_bones=flops_null,
                seconds_morph=t_morph, seconds_null_bones=t_null,
                max_error=float(errs.max()) if errs.size else 0.0,
                rms_error=float(np.sqrt(np.mean(errs ** 2))) if errs.size else 0.0,
                relative_error=float(errs.max() / disp) if disp > 0 else 0.0,
                max_displacement=disp, normal_error_deg=nerr)


# ---------------------------------------------------------------------------------------------- faces that move
#: null bones per LOD of the null-bone face (the talk's alternative to morph targets)
FACE_NULL_BONES = 8


def face_weights(names: Sequence[str], t: float, riders: npt.ArrayLike) -> np.ndarray:
    """A procedural face animation: morph weights ``(n, k) float32`` at ``t`` seconds for the
    riders ``riders (n,)`` (their indices: each rider keeps its own rhythm).

    Targets named ``blink`` close the eyes for 0.15 s every 2.8-4.0 s; ``smile`` and ``shout`` (the
    mouth) come and go on slower cycles, never both at once.  Any other target (a glTF model's
    expressions, e.g. RobotExpressive's Angry / Surprised / Sad) takes its turn in a cycle: each
    fades in, holds and fades out over 2 s.
    """
    names = [str(n).lower() for n in names]
    r = np.asarray(riders, dtype=np.float64).reshape(-1)
    t = float(t)
    out = np.zeros((len(r), len(names)), np.float32)
    period = 2.8 + 0.4 * (r % 4)
    ph = np.mod(t + 0.77 * r, period)
    blink = np.clip(1.0 - np.abs(ph - 0.075) / 0.075, 0.0, 1.0)  # a 0.15 s triangle at the start of each period
    mouth = 0.5 - 0.5 * np.cos(2.0 * np.pi * (t + 1.3 * r) / 5.0)  # 0..1 over 5 s
    which = np.mod(np.floor((t + 1.3 * r) / 5.0), 2.0)  # smile, then shout
    others = [i for i, n in enumerate(names) if n not in ("blink", "smile", "shout")]
    for i, n in enumerate(names):
        if n == "blink":
            out[:, i] = blink
        elif n == "smile":
            out[:, i] = mouth * (which == 0)
        elif n == "shout":
            out[:, i] = mouth * (which == 1)
    if others:
        slot = np.floor((t + 0.9 * r) / 2.0).astype(np.int64) % len(others)
        x = np.mod(t + 0.9 * r, 2.0) / 2.0
        env = np.clip(np.minimum(x, 1.0 - x) * 4.0, 0.0, 1.0)  # fade in 0.5 s, hold, fade out 0.5 s
        for j, i in enumerate(others):
            out[:, i] = np.where(slot == j, env, 0.0)
    return out


class FaceSkin:
    """Faces that move on blended-matrix skinned riders: morph targets (or their null-bone fit)
    added after skinning.

    Skinning is linear in the bind-space position, so ``skin(p + d) = skin(p) + R d`` with ``R``
    the rotation part of the vertex's palette matrix: only the ``m`` vertices a target moves are
    touched, ``(n, m, 3, 3) @ (n, m, 3)`` per frame.  ``mode="morph"`` blends the targets
    (:func:`blend_morphs`, normals too); ``mode="null_bones"`` displaces by the translation-only
    null bones fitted to them (:func:`morphs_to_null_bones`; normals unchanged, as on the PS2).

    Parameters
    ----------
    mesh : the LOD's SkinnedMesh (with ``morph_positions``);  palette_index : (v,) its palette entries
    mode : "morph" | "null_bones";  n_bones : null bones of the fit
    """

    def __init__(self, mesh: Any, palette_index: npt.ArrayLike, mode: str = "morph", n_bones: int = FACE_NULL_BONES) -> None:
        if mode not in ("morph", "null_bones"):
            raise ValidationError(f"face mode must be 'morph' or 'null_bones', got {mode!r}")
        self.mode = mode
        self.names = list(mesh.morph_names)
        self.k = int(mesh.morph_positions.shape[0])
        moved = np.nonzero(np.abs(mesh.morph_positions).sum(axis=(0, 2)) > 0)[0] if self.k else np.zeros(0, np.int64)
        self.index = np.asarray(palette_index)
        self.rig = None
        if mode == "null_bones" and self.k and len(moved):
            self.rig = morphs_to_null_bones(mesh, min(int(n_bones), len(moved)))
            self.vertices = self.rig.vertices.astype(np.int64)
        else:
            self.vertices = moved.astype(np.int64)
        self.dpos = np.ascontiguousarray(mesh.morph_positions[:, self.vertices], np.float32)  # (k, m, 3)
        self.dnrm = np.ascontiguousarray(mesh.morph_normals[:, self.vertices], np.float32)

    def __bool__(self) -> bool:
        return bool(self.k and len(self.vertices))

    def offsets(self, weights: npt.ArrayLike) -> np.ndarray:
        """Bind-space displacements ``(n, m, 3) float32`` of the moved vertices for ``weights (n, k)``."""
        w = np.asarray(weights, np.float32).reshape(-1, self.k)
        if self.rig is not None:
            t = np.einsum("nk,kjc->njc", w, self.rig.offsets)  # (n, J, 3) bone translations
            return np.einsum("mi,nmic->nmc", self.rig.weights, t[:, self.rig.joints])
        return np.einsum("nk,kmc->nmc", w, self.dpos)

    def apply(self, positions: np.ndarray, normals: np.ndarray, palette: np.ndarray, weights: npt.ArrayLike) -> None:
        """Add the face to skinned ``positions``/``normals (n, v, 3)`` in place, given this frame's
        ``palette (n, p, 3, 4)`` (:meth:`BlendedMesh.palette_matrices`) and ``weights (n, k)``."""
        if not self or not len(positions):
            return
        vs = self.vertices
        rot = palette[:, self.index[vs], :, :3]  # (n, m, 3, 3)
        positions[:, vs] += np.einsum("nmij,nmj->nmi", rot, self.offsets(weights))
        if self.rig is None:
            w = np.asarray(weights, np.float32).reshape(-1, self.k)
            dn = np.einsum("nmij,nmj->nmi", rot, np.einsum("nk,kmc->nmc", w, self.dnrm))
            nn = normals[:, vs] + dn
            normals[:, vs] = nn / np.maximum(np.linalg.norm(nn, axis=-1, keepdims=True), 1e-12)
