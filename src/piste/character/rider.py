"""The default rider: a procedural snowboarder, so demos need no external files.

``default_rider(seed=0) -> Model`` builds, deterministically from ``seed``:

- a 25-bone skeleton (root, board, pelvis, spine1-3, neck, head, jaw, clavicles, upper/lower
  arms, hands, thighs, shins, feet, toes), bind pose standing upright on the board, arms in an
  A-pose, all bone frames axis-aligned (rest rotations identity);
- one skinned mesh of ~3,000 triangles: torso, arms and legs lofted along their bones with
  varying (super)elliptic cross-sections, a deformed-sphere head with a nose, mitten hands, boots,
  and a rounded snowboard with kicked nose and tail; smooth weights (up to 4 influences, blended
  over a few centimetres at every joint); UVs into one 128x128 RGBA texture atlas (jacket,
  pants, face with eyes, mouth, goggles and beanie, gloves, boots, board graphic);
- three face morph targets: ``smile``, ``blink``, ``shout``;
- four looping clips authored as keyframed rotations per bone (root and pelvis also translate):
  ``ride`` (balanced stance, bobbing), ``crouch``, ``grab`` (air, back hand on the toe edge) and
  ``spin`` (a 360 in the air). Legs (and the grabbing arm) are posed by two-bone IK at each key
  so the boots stay on the board.

Units are metres, +Y up. The board lies along X (nose at +X, travel direction); the rider faces
+Z (the toe edge), left foot forward (regular stance). ``seed`` changes colours and proportions
(height +-4 %), never the topology, so the same seed gives identical arrays.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.character.model import Clip, Model, Skeleton, SkinnedMesh, Track
from piste.character.morph import vertex_normals
from piste.transforms import matrix_to_quat, quat_multiply, quat_conjugate, quat_normalize, quat_rotate

__all__ = ["default_rider", "RIDER_BONES", "RIDER_CLIPS", "RIDER_MORPHS"]

# name, parent, bind-pose joint position (metres, before the seed's height scale)
_BONES = [
    ("root", None, (0.0, 0.0, 0.0)),
    ("board", "root", (0.0, 0.0, 0.0)),
    ("pelvis", "root", (0.0, 0.97, 0.0)),
    ("spine1", "pelvis", (0.0, 1.07, 0.0)),
    ("spine2", "spine1", (0.0, 1.19, 0.0)),
    ("spine3", "spine2", (0.0, 1.31, 0.0)),
    ("neck", "spine3", (0.0, 1.48, 0.0)),
    ("head", "neck", (0.0, 1.57, 0.0)),
    ("jaw", "head", (0.0, 1.62, 0.03)),
    ("clavicle_l", "spine3", (0.03, 1.43, 0.0)),
    ("upperarm_l", "clavicle_l", (0.18, 1.43, 0.0)),
    ("lowerarm_l", "upperarm_l", (0.18 + 0.28 * 0.7071, 1.43 - 0.28 * 0.7071, 0.0)),
    ("hand_l", "lowerarm_l", (0.18 + 0.53 * 0.7071, 1.43 - 0.53 * 0.7071, 0.0)),
    ("clavicle_r", "spine3", (-0.03, 1.43, 0.0)),
    ("upperarm_r", "clavicle_r", (-0.18, 1.43, 0.0)),
    ("lowerarm_r", "upperarm_r", (-(0.18 + 0.28 * 0.7071), 1.43 - 0.28 * 0.7071, 0.0)),
    ("hand_r", "lowerarm_r", (-(0.18 + 0.53 * 0.7071), 1.43 - 0.53 * 0.7071, 0.0)),
    ("thigh_l", "pelvis", (0.09, 0.93, 0.0)),
    ("shin_l", "thigh_l", (0.175, 0.52, 0.0)),
    ("foot_l", "shin_l", (0.26, 0.11, 0.0)),
    ("toe_l", "foot_l", (0.26, 0.05, 0.11)),
    ("thigh_r", "pelvis", (-0.09, 0.93, 0.0)),
    ("shin_r", "thigh_r", (-0.175, 0.52, 0.0)),
    ("foot_r", "shin_r", (-0.26, 0.11, 0.0)),
    ("toe_r", "foot_r", (-0.26, 0.05, 0.11)),
]
RIDER_BONES = tuple(b[0] for b in _BONES)
RIDER_CLIPS = ("ride", "crouch", "grab", "spin")
RIDER_MORPHS = ("smile", "blink", "shout")
_B = {name: i for i, name in enumerate(RIDER_BONES)}

# texture atlas tiles (u0, v0, u1, v1) in [0, 1]
_TILES = {
    "jacket": (0.0, 0.0, 0.5, 0.25),
    "sleeve": (0.5, 0.0, 1.0, 0.25),
    "pants": (0.0, 0.25, 0.5, 0.5),
    "head": (0.5, 0.25, 1.0, 0.75),
    "glove": (0.0, 0.5, 0.25, 0.75),
    "boot": (0.25, 0.5, 0.5, 0.75),
    "board": (0.0, 0.75, 1.0, 1.0),
}

# head sphere: centre (before scaling) and radii; face towards +Z
_HEAD_C = np.array([0.0, 1.70, 0.012])
_HEAD_R = np.array([0.092, 0.118, 0.104])
_EYE = (0.57, 0.33)       # (v = theta/pi, azimuth in radians) of the eyes
_MOUTH = (0.36, 0.0)


# --------------------------------------------------------------------------- small math helpers
def _smoothstep(x: npt.ArrayLike) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _ramp(x: npt.ArrayLike, a: float, b: float) -> np.ndarray:
    """0 below a, 1 above b, smooth in between (a > b reverses it)."""
    return _smoothstep((np.asarray(x, dtype=np.float64) - a) / (b - a))


def _normalize(v: npt.ArrayLike) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _axis_angle(axis: npt.ArrayLike, degrees: float) -> np.ndarray:
    axis = _normalize(np.asarray(axis, dtype=np.float64))
    h = np.radians(degrees) / 2.0
    return np.concatenate([axis * np.sin(h), [np.cos(h)]])


def _qmul(*qs: npt.ArrayLike) -> np.ndarray:
    out = np.array([0.0, 0.0, 0.0, 1.0])
    for q in qs:
        out = quat_multiply(out, q)
    return quat_normalize(out)


def _swing(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Shortest-arc quaternion rotating unit vector ``u`` onto ``v``."""
    u, v = _normalize(u), _normalize(v)
    d = float(np.dot(u, v))
    if d < -0.999999:
        axis = np.cross(u, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(u, [0.0, 1.0, 0.0])
        return np.concatenate([_normalize(axis), [0.0]])
    return quat_normalize(np.concatenate([np.cross(u, v), [1.0 + d]]))


def _frames(centers: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangents and a rotation-minimising pair of normals ``(n, 3)`` each along a polyline."""
    c = np.asarray(centers, dtype=np.float64)
    t = np.gradient(c, axis=0)
    t = _normalize(t)
    ref = np.array([0.0, 0.0, 1.0]) if abs(t[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.empty_like(c)
    x[0] = _normalize(ref - np.dot(ref, t[0]) * t[0])
    for i in range(1, len(c)):  # a few dozen rings: construction time only
        xi = x[i - 1] - np.dot(x[i - 1], t[i]) * t[i]
        x[i] = _normalize(xi)
    y = np.cross(t, x)
    return t, x, y


# --------------------------------------------------------------------------- geometry parts
class _Part:
    """Vertices ``(n, 3)``, uv ``(n, 2)``, triangles ``(t, 3)`` (local indices), along/around
    parameters and a bone-weight matrix ``(n, B)`` filled in by the builder."""

    theta: np.ndarray  # the head part's polar / azimuth angles per vertex (set by the builder)
    phi: np.ndarray

    def __init__(self, name: str, pos: npt.ArrayLike, uv: npt.ArrayLike, tri: npt.ArrayLike, along: npt.ArrayLike, around: npt.ArrayLike,
                 dist: npt.ArrayLike | None = None) -> None:
        self.name = name
        self.pos = np.asarray(pos, dtype=np.float64)
        self.uv = np.asarray(uv, dtype=np.float64)
        self.tri = np.asarray(tri, dtype=np.int64)
        self.along = np.asarray(along, dtype=np.float64)
        self.around = np.asarray(around, dtype=np.float64)
        self.dist = self.along if dist is None else np.asarray(dist, dtype=np.float64)
        self.w = np.zeros((len(self.pos), len(RIDER_BONES)))


def _loft(name: str, centers: npt.ArrayLike, rx: npt.ArrayLike, ry: npt.ArrayLike, segments: int, tile: tuple[float, float, float, float],
          exponent: float = 2.0, xaxis: npt.ArrayLike | None = None, caps: tuple[bool, bool] = (True, True),
          cap_len: tuple[float, float] = (0.5, 0.5), around_offset: float = 0.0) -> _Part:
    """Sweep a superellipse along ``centers (n, 3)``.

    Ring ``i`` is ``c_i + rx_i * cx(a) * X_i + ry_i * cy(a) * Y_i`` with ``a`` in ``[0, 2 pi]``
    (seam column duplicated for the UVs). Caps are poles placed ``cap_len * r`` beyond the end
    rings along the tangent (rounded ends). UVs: ``u`` around, ``v`` along, mapped into ``tile``.
    """
    c = np.asarray(centers, dtype=np.float64)
    n = len(c)
    rx = np.broadcast_to(np.asarray(rx, dtype=np.float64), (n,))
    ry = np.broadcast_to(np.asarray(ry, dtype=np.float64), (n,))
    t, x, y = _frames(c)
    if xaxis is not None:  # orient the cross-section's X towards a given direction
        xa = np.asarray(xaxis, dtype=np.float64)
        x = _normalize(xa - np.sum(xa * t, axis=1, keepdims=True) * t)
        y = np.cross(t, x)
    m = segments
    a = np.linspace(0.0, 2.0 * np.pi, m + 1) + around_offset
    e = 2.0 / exponent
    ca, sa = np.cos(a), np.sin(a)
    cx = np.sign(ca) * np.abs(ca) ** e
    cy = np.sign(sa) * np.abs(sa) ** e
    ring = (c[:, None, :] + rx[:, None, None] * cx[None, :, None] * x[:, None, :]
            + ry[:, None, None] * cy[None, :, None] * y[:, None, :])  # (n, m+1, 3)
    seg = np.linalg.norm(np.diff(c, axis=0), axis=1)
    dist = np.concatenate([[0.0], np.cumsum(seg)])
    s = dist / max(dist[-1], 1e-12)
    pos = ring.reshape(-1, 3)
    along = np.repeat(s, m + 1)
    dist_v = np.repeat(dist, m + 1)
    around = np.tile(np.linspace(0.0, 1.0, m + 1), n)
    ii = np.arange(n - 1)[:, None] * (m + 1)
    jj = np.arange(m)[None, :]
    q0 = ii + jj
    q1 = q0 + 1
    q2 = q0 + (m + 1)
    q3 = q2 + 1
    tri = np.concatenate([np.stack([q0, q2, q1], -1).reshape(-1, 3),
                          np.stack([q1, q2, q3], -1).reshape(-1, 3)])
    extra_pos, extra_along, extra_dist, extra_tri = [], [], [], []
    nv = len(pos)
    if caps[0]:
        r0 = 0.5 * (rx[0] + ry[0])
        extra_pos.append(c[0] - t[0] * cap_len[0] * r0)
        extra_along.append(0.0)
        extra_dist.append(-cap_len[0] * r0)
        pole = nv + len(extra_pos) - 1
        j = np.arange(m)
        extra_tri.append(np.stack([np.full(m, pole), j, j + 1], -1))
    if caps[1]:
        r1 = 0.5 * (rx[-1] + ry[-1])
        extra_pos.append(c[-1] + t[-1] * cap_len[1] * r1)
        extra_along.append(1.0)
        extra_dist.append(dist[-1] + cap_len[1] * r1)
        pole = nv + len(extra_pos) - 1
        j = (n - 1) * (m + 1) + np.arange(m)
        extra_tri.append(np.stack([np.full(m, pole), j + 1, j], -1))
    if extra_pos:
        pos = np.concatenate([pos, np.array(extra_pos)])
        along = np.concatenate([along, extra_along])
        dist_v = np.concatenate([dist_v, extra_dist])
        around = np.concatenate([around, np.full(len(extra_pos), 0.5)])
        tri = np.concatenate([tri] + extra_tri)
    u0, v0, u1, v1 = tile
    uv = np.stack([u0 + (u1 - u0) * around, v0 + (v1 - v0) * np.clip(along, 0, 1)], -1)
    return _Part(name, pos, uv, tri, along, around, dist_v)


def _chain_weights(part: _Part, dist: np.ndarray, bones: list[str], joints_at: Sequence[Any],
                   width: Any) -> None:
    """Blend a chain of bones along ``dist``: bone k owns ``[joints_at[k], joints_at[k+1])``,
    transitions smoothed over ``+-width`` (scalar or per transition). Adds into ``part.w`` scaled
    by the weight still free (so earlier assignments keep priority)."""
    width = np.broadcast_to(np.asarray(width, dtype=np.float64), (len(bones),))
    edge = [np.zeros_like(dist)]
    for k in range(1, len(bones)):
        edge.append(_ramp(dist, joints_at[k] - width[k], joints_at[k] + width[k]))
    edge.append(np.ones_like(dist) * 0.0)
    w = np.zeros((len(dist), len(bones)))
    for k in range(len(bones)):
        lo = 1.0 if k == 0 else edge[k]
        hi = edge[k + 1] if k + 1 < len(bones) else 0.0
        w[:, k] = lo - hi
    w = np.clip(w, 0.0, None)
    free = 1.0 - part.w.sum(1)
    for k, b in enumerate(bones):
        part.w[:, _B[b]] += w[:, k] * free


def _build_parts(rng_scale: float, J: dict[str, np.ndarray]) -> list[_Part]:
    """All body parts in bind space; ``J`` maps bone name -> bind joint position (3,)."""
    parts = []
    # torso: crotch -> neck top, superelliptic cross-section, puffy jacket
    ys = np.array([0.86, 0.90, 0.95, 1.01, 1.08, 1.16, 1.24, 1.31, 1.37, 1.42, 1.46, 1.49, 1.53, 1.58, 1.63])
    rxs = np.array([0.07, 0.135, 0.160, 0.165, 0.158, 0.160, 0.172, 0.185, 0.190, 0.178, 0.120, 0.062, 0.052, 0.050, 0.048])
    rzs = np.array([0.06, 0.100, 0.112, 0.115, 0.112, 0.118, 0.126, 0.130, 0.122, 0.105, 0.080, 0.058, 0.050, 0.050, 0.048])
    zoff = np.array([0.0, 0.0, -0.005, -0.005, 0.0, 0.005, 0.012, 0.012, 0.008, 0.0, -0.005, -0.01, -0.012, -0.01, -0.005])
    cen = np.stack([np.zeros_like(ys), ys * rng_scale, zoff], -1)
    torso = _loft("torso", cen, rxs, rzs, 20, _TILES["jacket"], exponent=2.4, xaxis=[1.0, 0.0, 0.0],
                  caps=(True, True), cap_len=(0.4, 0.3), around_offset=0.0)
    y = torso.pos[:, 1]
    ax = np.abs(torso.pos[:, 0])
    # shoulders -> clavicles, hips -> thighs, then the spine chain for the rest
    side = torso.pos[:, 0] >= 0
    wc = _ramp(ax, 0.08, 0.16) * _ramp(y, J["spine3"][1] - 0.02, J["clavicle_l"][1] - 0.02)
    torso.w[:, _B["clavicle_l"]] = np.where(side, wc, 0)
    torso.w[:, _B["clavicle_r"]] = np.where(side, 0, wc)
    wt = 0.7 * _ramp(ax, 0.02, 0.12) * _ramp(y, J["pelvis"][1] + 0.01, J["thigh_l"][1] - 0.06)
    torso.w[:, _B["thigh_l"]] += np.where(side, wt, 0)
    torso.w[:, _B["thigh_r"]] += np.where(side, 0, wt)
    chain = ["pelvis", "spine1", "spine2", "spine3", "neck", "head"]
    _chain_weights(torso, y, chain, [0.0] + [J[b][1] for b in chain[1:]], [0, 0.05, 0.06, 0.06, 0.035, 0.02])
    parts.append(torso)

    # head: deformed sphere with nose and chin, face towards +Z
    nr, na = 15, 20
    th = np.linspace(0.0, np.pi, nr + 2)[1:-1]  # polar angle from the bottom
    ph = np.linspace(-np.pi, np.pi, na + 1)  # azimuth, 0 = front (+Z), seam at the back
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    hp = _head_surface(TH, PH, rng_scale)
    head_pos = hp.reshape(-1, 3)
    around = ((PH + np.pi) / (2 * np.pi)).reshape(-1)
    along = (TH / np.pi).reshape(-1)
    ii = np.arange(nr - 1)[:, None] * (na + 1)
    jj = np.arange(na)[None, :]
    q0 = ii + jj
    q1, q2 = q0 + 1, q0 + na + 1
    q3 = q2 + 1
    tri = [np.stack([q0, q1, q2], -1).reshape(-1, 3), np.stack([q1, q3, q2], -1).reshape(-1, 3)]
    bottom = _head_surface(np.array(0.0), np.array(0.0), rng_scale)
    top = _head_surface(np.array(np.pi), np.array(0.0), rng_scale)
    nv = head_pos.shape[0]
    j = np.arange(na)
    tri.append(np.stack([np.full(na, nv), j + 1, j], -1))
    jt = (nr - 1) * (na + 1) + j
    tri.append(np.stack([np.full(na, nv + 1), jt, jt + 1], -1))
    head_pos = np.concatenate([head_pos, bottom.reshape(1, 3), top.reshape(1, 3)])
    around = np.concatenate([around, [0.5, 0.5]])
    along = np.concatenate([along, [0.0, 1.0]])
    u0, v0, u1, v1 = _TILES["head"]
    uv = np.stack([u0 + (u1 - u0) * around, v0 + (v1 - v0) * along], -1)
    head = _Part("head", head_pos, uv, np.concatenate(tri), along, around)
    hy = head.pos[:, 1]
    theta = along * np.pi
    phi = around * 2 * np.pi - np.pi
    wj = 0.8 * _ramp(theta, np.pi * (_MOUTH[0] + 0.02), np.pi * (_MOUTH[0] - 0.1)) * _ramp(np.abs(phi), 1.2, 0.6)
    head.w[:, _B["jaw"]] = wj
    _chain_weights(head, hy, ["neck", "head"], [0.0, J["head"][1] + 0.015], [0, 0.03])
    head.theta, head.phi = theta, phi
    parts.append(head)

    for s, sx in (("l", 1.0), ("r", -1.0)):
        # arm: from inside the shoulder to the wrist, puffy sleeve with a cuff
        sh, el, wr = J[f"upperarm_{s}"], J[f"lowerarm_{s}"], J[f"hand_{s}"]
        d = _normalize(wr - sh)
        start = sh - d * 0.07
        ts = np.array([0.0, 0.05, 0.09, 0.14, 0.20, 0.26, 0.31, 0.35, 0.40, 0.46, 0.52, 0.565, 0.59])
        rad = np.array([0.060, 0.066, 0.064, 0.060, 0.056, 0.052, 0.050, 0.049, 0.047, 0.045, 0.044, 0.050, 0.048])
        cen = start[None, :] + ts[:, None] * d[None, :]
        arm = _loft(f"arm_{s}", cen, rad, rad * 0.92, 10, _TILES["sleeve"], exponent=2.0,
                    xaxis=[0.0, 0.0, 1.0], caps=(False, True), cap_len=(0.3, 0.15))
        dd = arm.dist - 0.07  # distance from the shoulder joint
        le = np.linalg.norm(el - sh)
        lw = np.linalg.norm(wr - sh)
        _chain_weights(arm, dd, [f"clavicle_{s}", f"upperarm_{s}", f"lowerarm_{s}", f"hand_{s}"],
                       [0.0, 0.0, le, lw], [0, 0.05, 0.05, 0.02])
        # the torso side of the sleeve also follows the chest a little
        arm.w[:, _B["spine3"]] += 0.0
        parts.append(arm)

        # mitten hand: flattened, slightly cupped, thumb side bulge
        ts = np.array([0.0, 0.03, 0.07, 0.11, 0.14, 0.165])
        rw = np.array([0.036, 0.046, 0.050, 0.048, 0.040, 0.025])
        rt = np.array([0.028, 0.030, 0.030, 0.027, 0.022, 0.015])
        cen = (wr - d * 0.01)[None, :] + ts[:, None] * d[None, :]
        hand = _loft(f"hand_{s}", cen, rw, rt, 8, _TILES["glove"], exponent=2.3,
                     xaxis=[0.0, 0.0, 1.0], caps=(True, True), cap_len=(0.3, 0.6))
        _chain_weights(hand, hand.dist, [f"lowerarm_{s}", f"hand_{s}"], [0.0, 0.02], [0, 0.02])
        parts.append(hand)

        # leg: baggy pants from inside the hip to the ankle cuff
        hip, kn, an = J[f"thigh_{s}"], J[f"shin_{s}"], J[f"foot_{s}"]
        d = _normalize(an - hip)
        start = hip - d * 0.06 + np.array([0.0, 0.0, 0.0])
        total = np.linalg.norm(an - hip) + 0.06 + 0.03
        ts = np.linspace(0.0, 1.0, 12) * total
        u = ts / total
        rad = np.interp(u, [0.0, 0.12, 0.3, 0.5, 0.57, 0.7, 0.88, 0.96, 1.0],
                        [0.085, 0.095, 0.086, 0.072, 0.070, 0.068, 0.072, 0.080, 0.080])
        cen = start[None, :] + ts[:, None] * d[None, :]
        cen[:, 2] += 0.012 * np.sin(np.pi * u)  # knees slightly forward
        leg = _loft(f"leg_{s}", cen, rad, rad * 0.95, 12, _TILES["pants"], exponent=2.0,
                    xaxis=[0.0, 0.0, 1.0], caps=(False, False))
        dd = leg.dist - 0.06
        lk = np.linalg.norm(kn - hip)
        la = np.linalg.norm(an - hip)
        _chain_weights(leg, dd, ["pelvis", f"thigh_{s}", f"shin_{s}", f"foot_{s}"],
                       [0.0, 0.02, lk, la + 0.02], [0, 0.05, 0.06, 0.02])
        parts.append(leg)

        # boot: along +Z (across the board), boxy cross-section, flat sole
        zs = np.array([-0.10, -0.085, -0.05, 0.0, 0.05, 0.10, 0.15, 0.19, 0.215])
        hts = np.array([0.10, 0.15, 0.19, 0.20, 0.16, 0.12, 0.10, 0.085, 0.06])
        wds = np.array([0.040, 0.052, 0.058, 0.060, 0.060, 0.058, 0.055, 0.048, 0.032])
        sole = 0.028
        cen = np.stack([np.full_like(zs, an[0]), sole + hts / 2, zs], -1)
        boot = _loft(f"boot_{s}", cen, wds, hts / 2, 10, _TILES["boot"], exponent=3.0,
                     xaxis=[sx, 0.0, 0.0], caps=(True, True), cap_len=(0.25, 0.25))
        bz = boot.pos[:, 2]
        by = boot.pos[:, 1]
        wsh = 0.6 * _ramp(by, 0.14, 0.24) * _ramp(bz, 0.08, 0.0)
        boot.w[:, _B[f"shin_{s}"]] = wsh
        _chain_weights(boot, bz, [f"foot_{s}", f"toe_{s}"], [-1.0, J[f"toe_{s}"][2]], [0, 0.04])
        parts.append(boot)

    # snowboard: rounded plank along X with sidecut, kicked nose and tail
    xs = np.concatenate([[-0.80, -0.795, -0.785], np.linspace(-0.76, 0.76, 13), [0.785, 0.795, 0.80]])
    half = 0.80
    tip = 0.62
    wid = np.where(np.abs(xs) > tip, 0.135 * np.sqrt(np.clip(1 - ((np.abs(xs) - tip) / (half - tip + 1e-3)) ** 2, 0.02, 1)),
                   0.135 - 0.012 * np.cos(np.pi * xs / (2 * tip)))
    kick = 0.9 * np.clip(np.abs(xs) - 0.56, 0, None) ** 2
    thick = 0.011 * np.ones_like(xs)
    cen = np.stack([xs, thick + kick, np.zeros_like(xs)], -1)
    board = _loft("board", cen, wid, thick, 8, _TILES["board"], exponent=6.0,
                  xaxis=[0.0, 0.0, 1.0], caps=(True, True), cap_len=(0.15, 0.15))
    board.w[:, _B["board"]] = 1.0
    parts.append(board)
    return parts


def _head_surface(theta: np.ndarray, phi: np.ndarray, scale: float) -> np.ndarray:
    """Head positions ``(..., 3)`` at polar angle ``theta`` (0 = bottom) and azimuth ``phi``
    (0 = front, +Z): an ellipsoid with a narrower chin, a flatter back and a nose bump."""
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    st, ct = np.sin(theta), -np.cos(theta)  # ct: -1 at bottom, +1 at top
    r = _HEAD_R.copy()
    front = np.cos(phi)
    # jaw narrower at the bottom, cranium fuller at the top
    rx = r[0] * (1.0 - 0.18 * np.clip(-ct, 0, 1) ** 1.5)
    rz = r[2] * (1.0 + 0.06 * np.clip(front, 0, 1) * (ct < 0.3) - 0.08 * np.clip(-front, 0, 1))
    x = rx * st * np.sin(phi)
    z = rz * st * np.cos(phi)
    yv = r[1] * ct
    # chin forward, nose bump
    z = z + 0.012 * np.exp(-((ct + 0.75) / 0.2) ** 2) * np.clip(front, 0, 1) ** 4
    nose = np.exp(-((ct + 0.05) / 0.16) ** 2 - (phi / 0.22) ** 2)
    z = z + 0.022 * nose
    pts = np.stack([x, yv, z], -1) + _HEAD_C
    pts[..., 1] = pts[..., 1] * scale
    return pts


def _face_morphs(head: _Part, scale: float) -> np.ndarray:
    """Position deltas ``(3, n, 3)`` of the head part's vertices for smile, blink, shout."""
    th, ph = head.theta, head.phi
    n = len(th)
    base = _head_surface(th, ph, scale)
    deltas = np.zeros((3, n, 3))
    ev, ea = _EYE
    mv, _ = _MOUTH
    # smile: mouth corners up and back, cheeks lifted
    for sgn in (1.0, -1.0):
        win = np.exp(-((th / np.pi - mv) / 0.07) ** 2 - ((ph - sgn * 0.3) / 0.22) ** 2)
        th2 = th + 0.13 * win
        ph2 = ph + sgn * 0.08 * win
        deltas[0] += _head_surface(th2, ph2, scale) - base
    deltas[0] += (_head_surface(th, ph, scale) - base)
    # blink: squash the eye region onto the eye line
    for sgn in (1.0, -1.0):
        win = np.exp(-((th / np.pi - ev) / 0.085) ** 2 - ((ph - sgn * ea) / 0.2) ** 2)
        th2 = th - (th - ev * np.pi) * 0.85 * win
        deltas[1] += _head_surface(th2, ph, scale) - base
    # shout: lower face drops, mouth opens wide, the chin moves forward a little
    low = _ramp(th / np.pi, mv + 0.03, mv - 0.08) * _ramp(np.abs(ph), 1.4, 0.5)
    lip = np.exp(-((th / np.pi - mv) / 0.05) ** 2 - (ph / 0.35) ** 2)
    th2 = th - 0.16 * low - 0.05 * lip
    ph2 = ph * (1 + 0.25 * lip)
    deltas[2] = _head_surface(th2, ph2, scale) - base
    deltas[2][:, 2] += 0.006 * low
    return deltas


# --------------------------------------------------------------------------- texture
def _texture(rng: np.random.Generator) -> np.ndarray:
    """128x128 RGBA atlas ``(h, w, 4) uint8``; row 0 is v = 0 (glTF: v down the image)."""
    size = 128
    tex = np.zeros((size, size, 4), np.uint8)
    tex[..., 3] = 255
    jackets = [(214, 52, 38), (30, 120, 200), (250, 180, 30), (40, 160, 90), (150, 60, 170), (240, 100, 20)]
    pants = [(35, 40, 60), (60, 60, 65), (20, 70, 60), (200, 200, 205), (90, 50, 30)]
    jc = np.array(jackets[rng.integers(len(jackets))])
    pc = np.array(pants[rng.integers(len(pants))])
    bc = np.array([(20, 20, 20), (230, 230, 235), (200, 30, 60), (20, 90, 200)][rng.integers(4)])
    skin = np.array([(236, 192, 160), (198, 140, 100), (150, 100, 70), (250, 210, 180)][rng.integers(4)])
    v, u = np.mgrid[0:size, 0:size]
    uu = (u + 0.5) / size
    vv = (v + 0.5) / size

    def fill(tile: tuple[float, float, float, float], color: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u0, v0, u1, v1 = tile
        m = (uu >= u0) & (uu < u1) & (vv >= v0) & (vv < v1)
        tex[m, :3] = color
        return m, (uu - u0) / (u1 - u0), (vv - v0) / (v1 - v0)

    m, lu, lv = fill(_TILES["jacket"], jc)
    tex[m & (np.abs(lv - 0.62) < 0.04), :3] = 245  # chest stripe
    tex[m & (np.abs(lu - 0.25) < 0.012) & (lv > 0.2) & (lv < 0.75), :3] = (jc * 0.6).astype(np.uint8)  # zip
    m, lu, lv = fill(_TILES["sleeve"], jc)
    tex[m & (np.abs(lv - 0.5) < 0.05), :3] = 245
    m, lu, lv = fill(_TILES["pants"], pc)
    tex[m & (lv > 0.93), :3] = (pc * 0.7).astype(np.uint8)
    fill(_TILES["glove"], (25, 25, 28))
    m, lu, lv = fill(_TILES["boot"], (55, 55, 60))
    tex[m & (np.abs(lu - 0.5) > 0.2) & (lv > 0.3), :3] = (180, 40, 40)
    m, lu, lv = fill(_TILES["head"], skin)
    # face features on the head tile: u = (phi + pi) / 2 pi (front at 0.5), v = theta / pi
    phi = (lu - 0.5) * 2 * np.pi
    ev, ea = _EYE
    for sgn in (1.0, -1.0):
        e = ((phi - sgn * ea) / 0.16) ** 2 + ((lv - ev) / 0.045) ** 2
        tex[m & (e < 1.0), :3] = 250
        e2 = ((phi - sgn * ea) / 0.07) ** 2 + ((lv - ev) / 0.03) ** 2
        tex[m & (e2 < 1.0), :3] = (40, 60, 90)
        br = ((phi - sgn * (ea + 0.02)) / 0.2) ** 2 + ((lv - ev - 0.075) / 0.015) ** 2
        tex[m & (br < 1.0), :3] = (70, 45, 30)
    mo = (phi / 0.3) ** 2 + ((lv - _MOUTH[0]) / 0.025) ** 2
    tex[m & (mo < 1.0), :3] = (150, 50, 50)
    tex[m & (lv > 0.71), :3] = (bc * 0.5 + np.array([60, 60, 60])).clip(0, 255).astype(np.uint8)  # beanie
    strap = m & (np.abs(lv - 0.74) < 0.03)
    tex[strap, :3] = (30, 30, 30)
    lens = strap & (np.abs(phi) < 0.9) | (m & (np.abs(lv - 0.745) < 0.045) & (np.abs(phi) < 0.75))
    tex[lens, :3] = (255, 150, 30)
    tex[m & (lv > 0.95), :3] = (240, 240, 240)  # pompom
    m, lu, lv = fill(_TILES["board"], (235, 235, 240))
    tex[m & (np.abs(lv - 0.5) > 0.3), :3] = bc  # rails / base colour
    tex[m & (np.abs(np.sin(lu * 18.0)) > 0.85) & (np.abs(lv - 0.5) < 0.3), :3] = (bc * 0.5 + 100).astype(np.uint8)
    return tex


# --------------------------------------------------------------------------- skeleton and mesh
def _joint_positions(scale: float) -> dict[str, np.ndarray]:
    return {name: np.array(p, dtype=np.float64) * np.array([1.0, scale, 1.0]) for name, _, p in _BONES}


def _skeleton(J: dict[str, np.ndarray]) -> Skeleton:
    names = list(RIDER_BONES)
    parents = [(-1 if p is None else _B[p]) for _, p, _ in _BONES]
    world = np.array([J[n] for n in names])
    rest_t = np.array([world[i] - (world[p] if p >= 0 else 0.0) for i, p in enumerate(parents)])
    b = len(names)
    ib = np.tile(np.eye(4), (b, 1, 1))
    ib[:, :3, 3] = -world
    return Skeleton(names, np.asarray(parents), rest_t, np.tile([0.0, 0.0, 0.0, 1.0], (b, 1)), np.ones((b, 3)), ib)


def _welded_normals(pos: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Smooth normals that agree across duplicated (seam) vertices."""
    key = np.round(pos / 1e-6).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    upos = np.zeros((inv.max() + 1, 3))
    upos[inv] = pos
    un = vertex_normals(upos, inv[tri])
    return un[inv]


def _top4(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``(v, B)`` weights -> ``joints (v, 4) uint16``, ``weights (v, 4) float32`` (rows sum 1)."""
    order = np.argsort(-w, axis=1, kind="stable")[:, :4]
    ww = np.take_along_axis(w, order, axis=1)
    ww[ww < 0.02] = 0.0  # drop slivers
    ww /= ww.sum(1, keepdims=True)
    j = np.where(ww > 0, order, 0)
    return j.astype(np.uint16), ww.astype(np.float32)


# --------------------------------------------------------------------------- animation authoring
def _solve_two_bone(root: np.ndarray, target: np.ndarray, l1: Any, l2: Any,
                    hint: npt.ArrayLike) -> np.ndarray:
    """Middle joint position for a two-bone chain from ``root`` reaching ``target``."""
    d_vec = target - root
    d = float(np.linalg.norm(d_vec))
    d = min(max(d, abs(l1 - l2) + 1e-4), l1 + l2 - 1e-4)
    e = _normalize(d_vec)
    a = (l1 * l1 - l2 * l2 + d * d) / (2 * d)
    r = np.sqrt(max(l1 * l1 - a * a, 0.0))
    p = _normalize(hint - np.dot(hint, e) * e)
    return root + a * e + r * p


def _world_rot(sk: Skeleton, pose: Any) -> tuple[np.ndarray, np.ndarray]:
    """World rotation quaternions ``(b, 4)`` and positions ``(b, 3)`` of ``pose``."""
    w = sk.world_matrices(pose)
    return quat_normalize(matrix_to_quat(w[:, :3, :3])), w[:, :3, 3]


def _ik_limb(sk: Skeleton, pose: Any, J: dict[str, np.ndarray], upper: str, lower: str, end: str, target: np.ndarray, hint: npt.ArrayLike,
            end_world_rot: np.ndarray | None = None) -> None:
    """Set ``upper``/``lower`` local rotations so the ``end`` joint reaches ``target`` (world),
    bending towards ``hint``; optionally give ``end`` a world rotation."""
    iu, il, ie = _B[upper], _B[lower], _B[end]
    wq, wp = _world_rot(sk, pose)
    pu = sk.parents[iu]
    root = wp[iu]
    l1 = np.linalg.norm(J[lower] - J[upper])
    l2 = np.linalg.norm(J[end] - J[lower])
    mid = _solve_two_bone(root, target, l1, l2, hint)
    q_upper_w = _swing(J[lower] - J[upper], mid - root)
    pose.rotation[iu] = _qmul(quat_conjugate(wq[pu]), q_upper_w)
    # the lower bone's rest direction, in its own (world-aligned at rest) frame
    q_lower_w = _qmul(_swing(quat_rotate(q_upper_w, J[end] - J[lower]), target - mid), q_upper_w)
    pose.rotation[il] = _qmul(quat_conjugate(q_upper_w), q_lower_w)
    if end_world_rot is not None:
        pose.rotation[ie] = _qmul(quat_conjugate(q_lower_w), end_world_rot)


_X, _Y, _Z = np.eye(3)


def _key_pose(sk: Skeleton, J: dict[str, np.ndarray], clip: str, phase: float) -> Any:
    """The pose of ``clip`` at ``phase`` in [0, 1) (a looping cycle)."""
    pose = sk.rest_pose()
    c = np.cos(2 * np.pi * phase)
    s2 = np.sin(2 * np.pi * phase)
    R = pose.rotation
    T = pose.translation
    lift = 0.0
    spin = 0.0
    if clip == "ride":
        crouch = 0.10 + 0.025 * c
        twist, lean, head_turn = 22 + 4 * s2, 12 + 2 * c, 55
        arm_l = (_qmul(_axis_angle(_Z, 28 + 6 * s2), _axis_angle(_Y, -25)), 25)
        arm_r = (_qmul(_axis_angle(_Z, -20 - 5 * s2), _axis_angle(_Y, 30)), 30)
        board_tilt = 3 * s2
    elif clip == "crouch":
        k = 0.5 - 0.5 * c  # 0 -> 1 -> 0
        crouch = 0.08 + 0.20 * k
        twist, lean, head_turn = 15 + 10 * k, 14 + 22 * k, 50 - 10 * k
        arm_l = (_qmul(_axis_angle(_Z, 20 - 10 * k), _axis_angle(_Y, -60 * k - 10), _axis_angle(_X, -30 * k)), 20 + 40 * k)
        arm_r = (_qmul(_axis_angle(_Z, -20 + 10 * k), _axis_angle(_Y, 60 * k + 10), _axis_angle(_X, -30 * k)), 20 + 40 * k)
        board_tilt = 0.0
    elif clip == "grab":
        k = np.sin(np.pi * phase) ** 2
        lift = 0.45 * np.sin(np.pi * phase)
        crouch = 0.10 + 0.36 * k
        twist, lean, head_turn = 18 - 18 * k, 14 + 40 * k, 60
        arm_l = (_qmul(_axis_angle(_Z, 40 + 30 * k), _axis_angle(_Y, -30)), 20 + 10 * k)
        arm_r = None  # IK to the toe edge
        board_tilt = -18 * k
    elif clip == "spin":
        k = np.sin(np.pi * phase) ** 2
        lift = 0.55 * np.sin(np.pi * phase)
        spin = 360.0 * phase
        crouch = 0.10 + 0.16 * k
        twist, lean, head_turn = 22 + 25 * k, 12 + 10 * k, 55 + 20 * k
        arm_l = (_qmul(_axis_angle(_Z, 30 + 40 * k), _axis_angle(_Y, -50 * k)), 30)
        arm_r = (_qmul(_axis_angle(_Z, -30 - 40 * k), _axis_angle(_Y, 50 * k)), 30)
        board_tilt = 0.0
    else:  # pragma: no cover - internal
        raise ValueError(clip)
    T[_B["root"], 1] += lift
    R[_B["root"]] = _axis_angle(_Y, spin)
    R[_B["board"]] = _axis_angle(_X, board_tilt)
    T[_B["pelvis"], 1] -= crouch
    T[_B["pelvis"], 2] -= 0.35 * crouch  # hips back as the knees go forward
    R[_B["pelvis"]] = _axis_angle(_Y, twist * 0.4)
    per = [_qmul(_axis_angle(_Y, twist * 0.2), _axis_angle(_X, lean / 3.0))] * 3
    for i, b in enumerate(("spine1", "spine2", "spine3")):
        R[_B[b]] = per[i]
    R[_B["neck"]] = _qmul(_axis_angle(_Y, head_turn * 0.4), _axis_angle(_X, -lean * 0.35))
    R[_B["head"]] = _qmul(_axis_angle(_Y, head_turn * 0.6 - twist), _axis_angle(_X, -lean * 0.35))
    for side, arm in (("l", arm_l), ("r", arm_r)):
        if arm is None:
            continue
        q, elbow = arm
        R[_B[f"upperarm_{side}"]] = q
        R[_B[f"lowerarm_{side}"]] = _axis_angle(_Y if side == "l" else -_Y, -elbow)
    wq, wp = _world_rot(sk, pose)
    board_w = sk.world_matrices(pose)[_B["board"]]
    for side in ("l", "r"):
        ankle = (board_w @ np.append(J[f"foot_{side}"], 1.0))[:3]
        hint = quat_rotate(wq[_B["board"]], np.array([0.25 if side == "l" else -0.25, 0.0, 1.0]))
        _ik_limb(sk, pose, J, f"thigh_{side}", f"shin_{side}", f"foot_{side}", ankle, hint,
                 end_world_rot=wq[_B["board"]])
    if clip == "grab":  # back (right) hand grabs the toe edge between the feet
        target = (board_w @ np.array([-0.06, 0.10, 0.15, 1.0]))[:3]
        wq, wp = _world_rot(sk, pose)
        hand_target = target
        hint = quat_rotate(wq[_B["board"]], np.array([-1.0, 0.6, 0.4]))
        blend = k
        if blend > 0.05:
            # reach only as far as the grab amount: interpolate from a relaxed hand position
            relaxed = wp[_B["upperarm_r"]] + quat_rotate(wq[_B["spine3"]], np.array([-0.30, -0.35, 0.15]))
            hand_target = relaxed + (target - relaxed) * blend
        else:
            hand_target = wp[_B["upperarm_r"]] + quat_rotate(wq[_B["spine3"]], np.array([-0.30, -0.35, 0.15]))
        _ik_limb(sk, pose, J, "upperarm_r", "lowerarm_r", "hand_r", hand_target, hint)
    return pose


_DURATIONS = {"ride": 2.0, "crouch": 1.6, "grab": 1.6, "spin": 1.2}
_KEYS = {"ride": 9, "crouch": 9, "grab": 11, "spin": 13}


def key_tables(sk: Skeleton, J: dict[str, np.ndarray], name: str) -> tuple[np.ndarray, np.ndarray]:
    """The key poses of clip ``name``: ``rotation (b, n, 4)`` (a continuous quaternion path per
    bone) and ``translation (b, n, 3)``, float64, posed by the rig's IK."""
    n = _KEYS[name]
    phases = np.arange(n) / (n - 1)
    poses = [_key_pose(sk, J, name, ph % 1.0) for ph in phases[:-1]]
    poses.append(poses[0].copy())  # loop: last key repeats the first
    if name == "spin":  # keep the root's turn continuous through 360 degrees
        poses[-1].rotation[_B["root"]] = _axis_angle(_Y, 360.0)
    rot = np.stack([p.rotation for p in poses], 1)  # (b, n, 4)
    # make each bone's keys a continuous quaternion path (no sign flips)
    for k in range(1, n):
        flip = np.sum(rot[:, k] * rot[:, k - 1], axis=1) < 0
        rot[flip, k] *= -1
    tra = np.stack([p.translation for p in poses], 1)
    return rot, tra


#: the seed-0 rider's key tables (:func:`key_tables` of every clip), shipped with the package: the
#: rig's IK in Python took ~0.2 s of every process that made the default rider (``piste demo``'s
#: set-up); ``tests/character/test_rider.py`` checks the file against the code
RIDER_KEYS_FILE = Path(__file__).resolve().parents[1] / "data" / "rider_keys.npz"


def shipped_key_tables() -> dict | None:
    """``{clip: (rotation, translation)}`` from :data:`RIDER_KEYS_FILE`, or None when it is missing,
    unreadable or of another shape (then the keys are posed)."""
    try:
        with np.load(RIDER_KEYS_FILE, allow_pickle=False) as z:
            out = {n: (z[f"{n}/rotation"], z[f"{n}/translation"]) for n in RIDER_CLIPS}
    except Exception:  # noqa: BLE001 - any unreadable file: pose the keys instead
        return None
    b = len(RIDER_BONES)
    if any(r.shape != (b, _KEYS[n], 4) or t.shape != (b, _KEYS[n], 3) or r.dtype != np.float64 or t.dtype != np.float64
           for n, (r, t) in out.items()):
        return None
    return out


def write_key_tables(path: str | os.PathLike[str] = RIDER_KEYS_FILE) -> Path:
    """Pose the seed-0 rider's keys and write them to ``path`` (regenerates the shipped file)."""
    J = _joint_positions(1.0)
    sk = _skeleton(J)
    arrays: dict[str, Any] = {}
    for n in RIDER_CLIPS:
        arrays[f"{n}/rotation"], arrays[f"{n}/translation"] = key_tables(sk, J, n)
    path = Path(path)
    with open(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path


def _clips(sk: Skeleton, J: dict[str, np.ndarray], scale: float = 1.0) -> dict[str, Clip]:
    clips = {}
    shipped = shipped_key_tables() if scale == 1.0 else None
    for name in RIDER_CLIPS:
        n = _KEYS[name]
        dur = _DURATIONS[name]
        phases = np.arange(n) / (n - 1)
        rot, tra = shipped[name] if shipped is not None else key_tables(sk, J, name)
        rot, tra = rot.copy(), tra.copy()
        times = phases * dur
        tracks = {}
        rest_q = np.array([0.0, 0.0, 0.0, 1.0])
        for i, bname in enumerate(RIDER_BONES):
            bt = {}
            if np.abs(np.abs(rot[i] @ rest_q) - 1.0).max() > 1e-9:
                bt["rotation"] = Track(times, rot[i], "LINEAR")
            if np.abs(tra[i] - sk.rest_translation[i]).max() > 1e-9:
                bt["translation"] = Track(times, tra[i], "LINEAR")
            if bt:
                tracks[bname] = bt
        clips[name] = Clip(name=name, duration=dur, tracks=tracks, skeleton=sk)
    return clips


def _outward(pos: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Triangles ``(t, 3)`` of one part wound so its signed volume (divergence theorem about the
    part's centre) is positive: the part faces outward, and normals computed from it point out."""
    p = pos - pos.mean(axis=0)
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    return tri[:, ::-1].copy() if np.einsum("ij,ij->", a, np.cross(b, c)) < 0 else tri


def default_rider(seed: int = 0) -> Model:
    """Build piste's procedural snowboarder (deterministic for a given ``seed``).

    Returns a :class:`Model` named ``"rider"`` with a 25-bone :class:`Skeleton`, one
    :class:`SkinnedMesh` ``"rider"`` (~3,000 triangles, 4 influences a vertex at most, UVs, an
    RGBA texture, morph targets ``smile``, ``blink``, ``shout``) and looping clips ``ride``,
    ``crouch``, ``grab``, ``spin`` (sample them with ``loop=True``).
    """
    rng = np.random.default_rng(int(seed))
    scale = float(1.0 + 0.04 * (2.0 * rng.random() - 1.0)) if seed else 1.0
    tex = _texture(rng)
    J = _joint_positions(scale)
    sk = _skeleton(J)
    parts = _build_parts(scale, J)
    pos_l: list[np.ndarray] = []
    uv_l: list[np.ndarray] = []
    tri_l: list[np.ndarray] = []
    w_l: list[np.ndarray] = []
    off = 0
    head_range = (0, 0)  # set from the head part below (there is always one)
    for p in parts:
        if p.name == "head":
            head_range = (off, off + len(p.pos))
        pos_l.append(p.pos)
        uv_l.append(p.uv)
        tri_l.append(_outward(p.pos, p.tri) + off)
        w_l.append(p.w)
        off += len(p.pos)
    pos = np.concatenate(pos_l)
    uv = np.concatenate(uv_l)
    tri = np.concatenate(tri_l)
    joints, weights = _top4(np.concatenate(w_l))
    normals = _welded_normals(pos, tri)
    head = parts[[p.name for p in parts].index("head")]
    k = len(RIDER_MORPHS)
    morph_pos = np.zeros((k, len(pos), 3))
    morph_pos[:, head_range[0]:head_range[1]] = _face_morphs(head, scale)
    morph_nrm = np.stack([_welded_normals(pos + morph_pos[i], tri) - normals for i in range(k)])
    mesh = SkinnedMesh(name="rider", positions=pos, indices=tri, normals=normals, uv=uv,
                       joints=joints, weights=weights, morph_positions=morph_pos,
                       morph_normals=morph_nrm, morph_names=list(RIDER_MORPHS), texture=tex,
                       base_color=np.ones(4, np.float32), skinned=True, group="rider")
    return Model(name="rider", skeleton=sk, meshes=[mesh], clips=_clips(sk, J, scale))
