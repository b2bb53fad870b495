"""Sharing clips between rigs whose bone names differ: bone maps, a built-in map, a coverage warning.

A clip plays on another skeleton by bone name (:mod:`piste.character.animation`); when the names
differ nothing matches and the target silently stays in its rest pose.  This module renames a
clip's tracks (and its source skeleton, whose rest lengths drive the ``scaled`` retarget rule)
through a **bone map** ``{source bone: target bone}``:

* **explicit**: any dict (the API, or a scene file's ``bone_map`` table);
* **built-in** (``"builtin"``): both skeletons' bones are labelled with canonical roles (the
  default rider's names: ``pelvis``, ``spine1..3``, ``neck``, ``head``, ``clavicle_l``,
  ``upperarm_l``, ``lowerarm_l``, ``hand_l``, ``thigh_l``, ``shin_l``, ``foot_l``, ``toe_l`` and the
  ``_r`` side) and joined on them.  Labels come from the names when they say it (the rider's own
  names; Mixamo's ``mixamorig:LeftUpLeg``; SSX Tricky's ``hips``, ``l_clav``, ``l_thigh``, ``r_calf``; ``Left``/``Right``/``.L``/``_R``/``L``-suffixed
  names like ``UpperArm.L``, ``b_LeftForeArm_010``, ``thigh_l``), and otherwise from the
  **hierarchy and rest geometry** (files whose joints are just ``node12``, like CesiumMan): the
  pelvis is the first bone with three long chains below it (two legs and the spine), the chest
  the spine bone where two arms and the neck branch, the neck chain is the branch most aligned
  with pelvis -> chest, and left/right follow from the toes' forward direction
  (``left = up x forward``; without toes, glTF's +Z forward).  A spine chain of any length is
  labelled ``spine1`` (first), ``spine3`` (the chest) and ``spine2`` (between).
* **coverage warning**: :func:`check_coverage` warns (:class:`RetargetWarning`) naming the
  target's unmatched bones when a clip drives fewer than half of the target's joints --
  :meth:`piste.character.Clip.sample` calls it when a clip plays on a foreign skeleton.

API
---
::

    bone_roles(skeleton) -> {bone name: role}
    builtin_bone_map(source, target) -> {source bone: target bone}
    resolve_bone_map(bone_map, source, target) -> dict    ("builtin", a dict, or None = same names)
    retarget_clip(clip, target, bone_map="builtin", source=None, warn=True, mode=None) -> Clip
        mode "world": each mapped bone turns in world space as its source bone does (rigs whose bone
        frames differ, e.g. an SSX Tricky rig vs the default rider), baked at the clip's key times
    add_clips(model, source_model, bone_map="builtin", clips=None, mode="relative") -> Model
    coverage(clip, target) -> (driven, unmatched)         target joint names
    check_coverage(clip, target, min_fraction=0.5)        warn when fewer than half are driven
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from piste.character.animation import sample_poses
from piste.character.coverage import RetargetWarning, check_coverage, coverage
from piste.errors import ConfigError
from piste.transforms import quat_conjugate, quat_multiply, quat_normalize, quat_rotate

if TYPE_CHECKING:  # (types only: this module stays importable without model.py's imports)
    from piste.character.model import Clip, Model, Skeleton

__all__ = ["RetargetWarning", "ROLES", "bone_roles", "builtin_bone_map", "resolve_bone_map", "retarget_clip", "add_clips",
           "coverage", "check_coverage"]

_LIMBS = ("clavicle", "upperarm", "lowerarm", "hand", "thigh", "shin", "foot", "toe")
ROLES = ("root", "pelvis", "spine1", "spine2", "spine3", "neck", "head") + tuple(
    f"{p}_{s}" for s in ("l", "r") for p in _LIMBS)

#: Mixamo's names (after the ``mixamorig:`` prefix) -> roles
MIXAMO = {"Hips": "pelvis", "Spine": "spine1", "Spine1": "spine2", "Spine2": "spine3", "Neck": "neck", "Head": "head"}
for _side, _s in (("Left", "l"), ("Right", "r")):
    MIXAMO.update({f"{_side}Shoulder": f"clavicle_{_s}", f"{_side}Arm": f"upperarm_{_s}",
                   f"{_side}ForeArm": f"lowerarm_{_s}", f"{_side}Hand": f"hand_{_s}", f"{_side}UpLeg": f"thigh_{_s}",
                   f"{_side}Leg": f"shin_{_s}", f"{_side}Foot": f"foot_{_s}", f"{_side}ToeBase": f"toe_{_s}"})

#: words (side tokens removed, lower case, no digits) -> role stem
_WORDS = {
    "hips": "pelvis", "hip": "pelvis", "pelvis": "pelvis",
    "spine": "spine", "abdomen": "spine", "chest": "spine", "upperspine": "spine", "lowerspine": "spine",
    "neck": "neck", "head": "head",
    "clavicle": "clavicle", "collar": "clavicle", "shoulder": "clavicle",
    "upperarm": "upperarm", "uparm": "upperarm", "arm": "upperarm",
    "lowerarm": "lowerarm", "forearm": "lowerarm",
    "hand": "hand", "palm": "hand", "wrist": "hand",
    "thigh": "thigh", "upleg": "thigh", "upperleg": "thigh",
    "shin": "shin", "calf": "shin", "lowerleg": "shin", "leg": "shin", "knee": "shin",
    "foot": "foot", "ankle": "foot",
    "toe": "toe", "toes": "toe", "toebase": "toe", "ball": "toe",
    # SSX Tricky's rider bones (``hips``, ``l_clav``, ``l_thigh``, ...: OpenSlope spec 240) and kin
    "clav": "clavicle", "clavical": "clavicle", "torso": "spine", "waist": "spine", "skull": "head",
    "bicep": "upperarm", "uarm": "upperarm", "farm": "lowerarm", "forarm": "lowerarm", "lowarm": "lowerarm",
    "elbow": "lowerarm",
}
#: numbered chains: "<word><n>" -> role stem by n (Fox's b_LeftLeg01 / 02, b_LeftFoot01 / 02)
_NUMBERED = {("leg", 1): "thigh", ("leg", 2): "shin", ("foot", 1): "foot", ("foot", 2): "toe"}


def _tokens(name: str) -> list[str]:
    n = re.split(r"[:|]", name)[-1]  # mixamorig:Hips, Armature|Hips
    n = re.sub(r"^(b_|bip0?1[ _]?|skeleton_|def[-_]|org[-_])", "", n, flags=re.I)
    n = re.sub(r"(_end|\.\d{3})$", "", n, flags=re.I)
    parts = re.split(r"[\s_.\-]+|(?<=[a-z])(?=[A-Z])|(?<=[A-Za-z])(?=\d)|(?<=\d)(?=[A-Za-z])", n)
    return [p for p in parts if p]


def _name_role(name: str) -> str | None:
    base = re.split(r"[:|]", name)[-1]
    if base in ROLES:
        return base
    if base in MIXAMO:
        return MIXAMO[base]
    toks = _tokens(name)
    side = None
    words, nums = [], []
    for t in toks:
        tl = t.lower()
        if tl in ("l", "left"):
            side = "l"
        elif tl in ("r", "right"):
            side = "r"
        elif tl.isdigit():
            nums.append(int(tl))
        else:
            words.append(tl)
    word = "".join(words)
    if not word:
        return None
    # a trailing bone-order number like Fox's "_010" was stripped by _tokens only when after "_": keep the first
    n = nums[0] if nums else None
    stem = _NUMBERED.get((word, n)) if n is not None else None
    stem = stem or _WORDS.get(word)
    if stem is None:
        return None
    if stem in _LIMBS:
        return f"{stem}_{side}" if side else None
    if side:
        return None
    if stem == "spine":
        return "spine"  # numbered later along the chain
    return stem


def _children(parents: Sequence[int] | np.ndarray) -> list[list[int]]:
    ch: list[list[int]] = [[] for _ in range(len(parents))]
    for i, p in enumerate(parents):
        if p >= 0:
            ch[p].append(i)
    return ch


def _depth_below(ch: list[list[int]]) -> np.ndarray:
    d = np.zeros(len(ch), np.int64)
    for i in range(len(ch) - 1, -1, -1):  # parents come before children
        if ch[i]:
            d[i] = 1 + max(d[c] for c in ch[i])
    return d


def _chain(i: int, ch: list[list[int]], depth: np.ndarray, n: int) -> list[int]:
    out = [i]
    while len(out) < n and ch[out[-1]]:
        out.append(max(ch[out[-1]], key=lambda c: depth[c]))
    return out


def _structural_roles(sk: Skeleton) -> dict[int, str]:
    """Roles from the hierarchy and rest geometry (see the module docstring)."""
    par = np.asarray(sk.parents)
    ch = _children(par)
    depth = _depth_below(ch)
    pos = sk.world_matrices()[:, :3, 3]
    hips = next((i for i in range(len(par)) if sum(1 for c in ch[i] if depth[c] >= 2) >= 3), None)
    if hips is None:
        return {}
    big = sorted((c for c in ch[hips] if depth[c] >= 2), key=lambda c: -depth[c])

    def branch_point(i: int) -> int | None:  # first bone at or below i with >= 3 children that have children or are long
        stack = [i]
        while stack:
            j = stack.pop(0)
            if sum(1 for c in ch[j] if depth[c] >= 1) >= 3:
                return j
            stack.extend(ch[j])
        return None

    spine_child = next((c for c in big if branch_point(c) is not None), big[0])
    legs = [c for c in big if c != spine_child][:2]
    chest = branch_point(spine_child)
    roles = {hips: "pelvis"}
    if chest is None:
        return roles
    # spine chain from spine_child to chest
    chain = [chest]
    while chain[-1] != spine_child and par[chain[-1]] >= 0:
        chain.append(int(par[chain[-1]]))
    chain = chain[::-1]
    up = pos[chest] - pos[hips]
    up = up / max(np.linalg.norm(up), 1e-12)
    branches = [c for c in ch[chest] if depth[c] >= 1] or ch[chest]
    neck = max(branches, key=lambda c: float(np.dot(pos[_chain(c, ch, depth, 3)[-1]] - pos[chest], up)))
    arms = [c for c in branches if c != neck][:2]
    for k, b in enumerate(chain):
        roles[b] = "spine1" if k == 0 else ("spine3" if k == len(chain) - 1 else "spine2")
    nchain = _chain(neck, ch, depth, 2)
    roles[nchain[0]] = "neck" if len(nchain) > 1 else "head"
    if len(nchain) > 1:
        roles[nchain[1]] = "head"
    leg_chains = [_chain(c, ch, depth, 4) for c in legs]
    arm_chains = []
    for c in arms:
        a = _chain(c, ch, depth, 5)
        lengths = [np.linalg.norm(pos[a[k + 1]] - pos[a[k]]) for k in range(len(a) - 1)]
        has_clav = len(a) >= 4 and len(lengths) >= 2 and lengths[0] < 0.6 * lengths[1]
        arm_chains.append((a[:4] if has_clav else [None] + a[:3]))
    # forward from the toes (foot -> toe), else glTF's +Z (or -Y when Z is up)
    fwd = None
    toes = [lc for lc in leg_chains if len(lc) == 4]
    if toes:
        f = np.mean([pos[lc[3]] - pos[lc[2]] for lc in toes], axis=0)
        f = f - np.dot(f, up) * up
        if np.linalg.norm(f) > 1e-9:
            fwd = f / np.linalg.norm(f)
    if fwd is None:
        f = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.7 else np.array([0.0, -1.0, 0.0])
        fwd = f - np.dot(f, up) * up
        fwd = fwd / max(np.linalg.norm(fwd), 1e-12)
    left = np.cross(up, fwd)

    def side(chain_bones: Iterable[int | None]) -> str:
        b = next(x for x in chain_bones if x is not None)
        return "l" if np.dot(pos[b] - pos[hips], left) > 0 else "r"

    for lc in leg_chains:
        s = side(lc)
        for b, stem in zip(lc, ("thigh", "shin", "foot", "toe")):
            roles[b] = f"{stem}_{s}"
    for ac in arm_chains:
        s = side(ac)
        for ab, stem in zip(ac, ("clavicle", "upperarm", "lowerarm", "hand")):
            if ab is not None:
                roles[ab] = f"{stem}_{s}"
    return roles


def bone_roles(sk: Skeleton) -> dict[str, str]:
    """``{bone name: role}`` for the bones of ``sk`` that can be labelled (see the module docstring)."""
    roles: dict[int, str] = {}
    used = set()
    for i, n in enumerate(sk.names):
        r = _name_role(n)
        if r is not None and r not in used and (r == "spine" or r in ROLES):
            roles[i] = r
            if r != "spine":
                used.add(r)
    key = {"pelvis", "head", "thigh_l", "thigh_r", "upperarm_l", "upperarm_r"}
    if len(key & set(roles.values())) < 4:
        struct = _structural_roles(sk)
        taken = set(roles.values())
        for i, r in struct.items():
            if i not in roles and r not in taken:
                roles[i] = r
    # number a spine chain: first spine1, last spine3 (the chest), between spine2
    sp = [i for i in sorted(roles) if roles[i] == "spine"]
    if sp:  # with generic ones, names that are roles join the chain (SSX-style spine, spine1, chest)
        sp = [i for i in sorted(roles) if roles[i] in ("spine", "spine1", "spine2", "spine3")]
        for k, i in enumerate(sp):
            roles[i] = "spine1" if k == 0 else ("spine3" if k == len(sp) - 1 else "spine2")
        if len(sp) > 3:
            for i in sp[2:-1]:
                del roles[i]
    return {sk.names[i]: r for i, r in roles.items()}


def builtin_bone_map(source: Skeleton, target: Skeleton) -> dict[str, str]:
    """``{source bone: target bone}`` joined on :func:`bone_roles`; bones with the same name in both
    are mapped to themselves first, unless both are labelled with different roles (a false
    friend: the rider's ``spine1`` is not an SSX rig's ``spine1`` when that one is its chest)."""
    rs, rt = bone_roles(source), bone_roles(target)
    out = {n: n for n in source.names if target.get(n) is not None and (
        n not in rs or n not in rt or rs[n] == rt[n])}
    by_role = {r: n for n, r in rt.items()}
    mapped_targets = set(out.values())
    for n, r in rs.items():
        t = by_role.get(r)
        if n not in out and t is not None and t not in mapped_targets:
            out[n] = t
            mapped_targets.add(t)
    return out


def resolve_bone_map(bone_map: str | dict[str, str] | None, source: Skeleton, target: Skeleton) -> dict[str, str]:
    """A ``{source: target}`` dict from ``bone_map``: ``"builtin"``, a dict (checked against both
    skeletons), or None (names as they are)."""
    if bone_map is None:
        return {n: n for n in source.names if target.get(n) is not None}
    if isinstance(bone_map, str):
        if bone_map != "builtin":
            raise ConfigError(f"bone_map must be 'builtin' or a table of source bone = target bone, got {bone_map!r}")
        return builtin_bone_map(source, target)
    if not isinstance(bone_map, dict):
        raise ConfigError(f"bone_map must be 'builtin' or a table of source bone = target bone, got {type(bone_map).__name__}")
    bad_s = [k for k in bone_map if source.get(k) is None]
    bad_t = [v for v in bone_map.values() if target.get(v) is None]
    if bad_s:
        raise ConfigError(f"bone_map: no bone {bad_s[0]!r} in the clip's skeleton (it has {', '.join(source.names[:8])}, ...)")
    if bad_t:
        raise ConfigError(f"bone_map: no bone {bad_t[0]!r} in the target skeleton (it has {', '.join(target.names[:8])}, ...)")
    seen: dict[str, str] = {}
    for k, v in bone_map.items():
        if v in seen:
            raise ConfigError(f"bone_map: bones {seen[v]!r} and {k!r} both map to {v!r}")
        seen[v] = k
    return dict(bone_map)


def retarget_clip(clip: Clip, target: Skeleton, bone_map: str | dict[str, str] | None = "builtin",
                  source: Skeleton | None = None, warn: bool = True, name: str | None = None,
                  mode: str | None = None) -> Clip:
    """A copy of ``clip`` whose tracks are named for ``target``'s bones.

    ``source``: the clip's skeleton (default ``clip.skeleton``); ``bone_map``: see
    :func:`resolve_bone_map`.  With ``mode=None`` the returned clip's ``skeleton`` is the source
    skeleton with its bones renamed the same way (so the ``scaled``/``relative`` rules of
    :meth:`Clip.sample` compare the right rest bones); play it with ``clip.sample(t, target)``.
    With ``mode="relative"`` or ``"scaled"`` that rule is baked into the keys (exactly: both are
    affine in the key values, so LINEAR, STEP and CUBICSPLINE tangents transform alike) and the
    clip belongs to ``target`` (``clip.skeleton is target``). ``mode="world"``: every mapped
    target bone turns in world space by its source bone's world rotation from rest (so rigs whose
    bones carry different local frames move alike) and a tracked translation moves the joint by
    the source joint's world displacement (scaled by the rest-length ratio); unmapped bones keep
    their local rest pose; baked as LINEAR keys at every key time of the clip (plus a 60 Hz grid
    when a track is not LINEAR); scale tracks are not carried.  Warns (:class:`RetargetWarning`)
    when it drives fewer than half of the target's joints.
    """
    if mode not in (None, "relative", "scaled", "world"):
        raise ConfigError(f"retarget mode must be 'relative', 'scaled', 'world' or None, got {mode!r}")
    src = source if source is not None else clip.skeleton
    if src is None:
        raise ConfigError(f"clip {clip.name!r} has no skeleton: pass source=")
    m = resolve_bone_map(bone_map, src, target)
    tracks = {m[b]: dict(t) for b, t in clip.tracks.items() if b in m}
    taken = set(m.values())
    names = []
    for n in src.names:  # rename the source skeleton; unmapped bones keep a name that cannot collide
        if n in m:
            names.append(m[n])
        else:
            k = f"{n}#src"
            while k in taken:
                k += "_"
            names.append(k)
            taken.add(k)
    renamed = type(src)(names, src.parents, src.rest_translation, src.rest_rotation, src.rest_scale, src.inverse_bind,
                        src.node_index, src.is_joint)
    out = replace(clip, name=name or clip.name, tracks=tracks, skeleton=renamed)
    if mode == "world":
        out = replace(out, tracks=_bake_world(clip, src, renamed, target, set(m.values())), skeleton=target)
    elif mode is not None:
        out = replace(out, tracks=_bake(out.tracks, renamed, target, mode), skeleton=target)
    if warn:
        check_coverage(out, target)
    return out


def _world(parents: np.ndarray, t: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations ``(m, b, 4)`` and positions ``(m, b, 3)`` from local ``t (m, b, 3)``,
    ``r (m, b, 4)`` (parents first; scale ignored)."""
    wr, wp = np.empty_like(r), np.empty_like(t)
    for j, p in enumerate(parents):
        if p < 0:
            wr[:, j], wp[:, j] = r[:, j], t[:, j]
        else:
            wr[:, j] = quat_multiply(wr[:, p], r[:, j])
            wp[:, j] = wp[:, p] + quat_rotate(wr[:, p], t[:, j])
    return wr, wp


def _bake_world(clip: Clip, src: Skeleton, renamed: Skeleton, dst: Skeleton, mapped: set) -> dict:
    """LINEAR tracks for ``dst`` with the ``world`` rule (:func:`retarget_clip`): ``clip`` is the
    source clip on its skeleton ``src`` (all its tracks, mapped or not, move the source's joints),
    ``renamed`` is ``src`` with the mapped bones named for ``dst``."""
    tracks = [tr for bt in clip.tracks.values() for tr in bt.values()]
    if not tracks:
        return {}
    track = type(tracks[0])  # piste.character.model.Track (not imported: model imports this module)
    times = np.unique(np.concatenate([tr.times for tr in tracks]))
    if any(tr.interpolation != "LINEAR" for tr in tracks):
        times = np.unique(np.concatenate([times, np.arange(times[0], times[-1], 1.0 / 60.0)]))
    m = len(times)
    st, sr, _ = sample_poses(clip, times, src)
    rs_t, rs_r = src.rest_translation[None], src.rest_rotation[None]
    ws_r, ws_p = _world(src.parents, st, sr)
    ws_r0, ws_p0 = _world(src.parents, rs_t, rs_r)
    wt_r0, wt_p0 = _world(dst.parents, dst.rest_translation[None], dst.rest_rotation[None])
    moves = {renamed.names[bi] for b, bt in clip.tracks.items() if "translation" in bt and (bi := src.get(b)) is not None}
    wr = np.empty((m, dst.n_bones, 4))
    wp = np.empty((m, dst.n_bones, 3))
    out = {}
    for j, (name, p) in enumerate(zip(dst.names, dst.parents)):
        i = renamed.get(name) if name in mapped else None
        lt = np.broadcast_to(dst.rest_translation[j], (m, 3)).copy()
        if i is None:  # unmapped: its local rest pose under the posed parent
            lr = np.broadcast_to(dst.rest_rotation[j], (m, 4))
            wr[:, j] = lr if p < 0 else quat_multiply(wr[:, p], lr)
        else:
            delta = quat_multiply(ws_r[:, i], quat_conjugate(np.broadcast_to(ws_r0[0, i], (m, 4))))
            wr[:, j] = quat_normalize(quat_multiply(delta, np.broadcast_to(wt_r0[0, j], (m, 4))))
            lr = wr[:, j] if p < 0 else quat_normalize(quat_multiply(quat_conjugate(wr[:, p]), wr[:, j]))
            if name in moves:  # the joint moves by the source joint's world displacement, scaled
                ls = float(np.linalg.norm(src.rest_translation[i]))
                k = float(np.linalg.norm(dst.rest_translation[j])) / ls if ls > 1e-12 else 1.0
                want = wt_p0[0, j] + k * (ws_p[:, i] - ws_p0[0, i])
                lt = want if p < 0 else quat_rotate(quat_conjugate(wr[:, p]), want - wp[:, p])
        wp[:, j] = lt if p < 0 else wp[:, p] + quat_rotate(wr[:, p], lt)
        if i is not None:
            lr = np.array(lr)
            for k2 in range(1, m):  # neighbouring keys in one hemisphere (LINEAR blends them)
                if float(lr[k2] @ lr[k2 - 1]) < 0:
                    lr[k2] = -lr[k2]
            bt = {"rotation": track(times.copy(), lr, "LINEAR")}
            if name in moves:
                bt["translation"] = track(times.copy(), np.asarray(lt), "LINEAR")
            out[name] = bt
    return out


def _bake(tracks: dict, src: Skeleton, dst: Skeleton, mode: str) -> dict:
    """Tracks with the ``scaled`` / ``relative`` retarget rule applied to every key (and tangent)."""
    out = {}
    for bone, bt in tracks.items():
        i, j = src.get(bone), dst.get(bone)
        nb = {}
        f: Callable[..., np.ndarray]  # (v) -> mapped v; the lambdas bind their constants as defaults
        lin: Callable[..., np.ndarray]
        for path, tr in bt.items():
            if path == "rotation":
                if mode == "relative":
                    q = quat_multiply(dst.rest_rotation[j], quat_conjugate(src.rest_rotation[i]))
                    f = lambda v, q=q: quat_multiply(np.broadcast_to(q, v.shape), v)  # noqa: E731
                else:
                    f = lambda v: v  # noqa: E731
                lin = f
            elif path == "translation":
                ls = float(np.linalg.norm(src.rest_translation[i]))
                ratio = float(np.linalg.norm(dst.rest_translation[j])) / ls if ls > 1e-12 else 1.0
                if mode == "relative":
                    f = lambda v, a=dst.rest_translation[j], b=src.rest_translation[i], k=ratio: a + k * (v - b)  # noqa: E731
                else:
                    f = lambda v, k=ratio: k * v  # noqa: E731
                lin = lambda v, k=ratio: k * v  # noqa: E731
            else:  # scale
                if mode == "relative":
                    safe = np.where(np.abs(src.rest_scale[i]) > 1e-12, src.rest_scale[i], 1.0)
                    f = lambda v, a=dst.rest_scale[j], b=safe: a * v / b  # noqa: E731
                    lin = f
                else:
                    f = lin = lambda v: v  # noqa: E731
            kw = {}
            if tr.interpolation == "CUBICSPLINE":
                kw = {"in_tangents": lin(tr.in_tangents), "out_tangents": lin(tr.out_tangents)}
            nb[path] = type(tr)(tr.times.copy(), f(tr.values), tr.interpolation, **kw)
        out[bone] = nb
    return out


def add_clips(model: Model, source_model: Model, bone_map: str | dict[str, str] | None = "builtin",
              clips: Iterable[str] | None = None, mode: str = "relative", warn: bool = True) -> Model:
    """A copy of ``model`` with ``source_model``'s clips (all, or the names in ``clips``) retargeted
    onto it (baked with ``mode``) and added; a name the model already has gets the source model's
    name in front (``"Fox:Run"``)."""
    if model.skeleton is None or source_model.skeleton is None:
        raise ConfigError("add_clips: both models need a skeleton")
    names = list(source_model.clips) if clips is None else list(clips)
    missing = [n for n in names if n not in source_model.clips]
    if missing:
        raise ConfigError(f"{source_model.name}: no clip {missing[0]!r} (clips: {', '.join(source_model.clips)})")
    new = dict(model.clips)
    for n in names:
        key = n if n not in new else f"{source_model.name}:{n}"
        new[key] = retarget_clip(source_model.clips[n], model.skeleton, bone_map, source_model.skeleton, warn=warn,
                                 name=key, mode=mode)
    return replace(model, clips=new)
