"""Deterministic sampling for the bake's rays: counter-based uniforms, stratified cosine-weighted
hemisphere directions (gather rays) and directions to a disc (an area sun).

Every number comes from a hash of ``(seed, sample index, ray index, stream)`` (splitmix64's
finaliser), so a sample's rays are the same whatever batch, chunk or worker computes them.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from piste.errors import ValidationError

__all__ = ["hash_uniform", "strata_side", "frame", "cosine_directions", "disc_directions"]

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLD = np.uint64(0x9E3779B97F4A7C15)


def _mix(x: npt.NDArray[np.uint64] | np.uint64) -> npt.NDArray[np.uint64] | np.uint64:
    """splitmix64's finaliser on uint64 arrays (wrapping arithmetic)."""
    x = (x ^ (x >> np.uint64(30))) * _M1
    x = (x ^ (x >> np.uint64(27))) * _M2
    return x ^ (x >> np.uint64(31))


def hash_uniform(seed: int, a: npt.ArrayLike, b: npt.ArrayLike, stream: int) -> np.ndarray:
    """Deterministic uniforms in [0, 1) from integer counters: ``a (k, 1)`` and ``b (1, r)`` (any
    broadcastable uint64-able shapes) -> ``broadcast shape`` float64.  The same ``(seed, a, b,
    stream)`` always gives the same number, wherever it sits in a batch."""
    with np.errstate(over="ignore"):
        s = _mix(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) * _GOLD + np.uint64(stream))
        x = _mix(np.asarray(a, dtype=np.uint64) * _GOLD ^ s)
        x = _mix(x + np.asarray(b, dtype=np.uint64) * _M2 + s)
    return np.asarray((x >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0))


def strata_side(rays: int, what: str = "rays") -> int:
    """``s`` with ``s * s == rays`` (rays are ``s x s`` strata); a ValidationError otherwise."""
    rays = int(rays)
    s = math.isqrt(max(rays, 0))
    if rays < 1 or s * s != rays:
        raise ValidationError(f"{what}: expected a square number of rays (1, 4, 9, 16, 64, ...), got {rays}")
    return s


def frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents ``(k, 3)`` completing unit normals ``n (k, 3)`` to an orthonormal frame
    (Duff et al. 2017, branchless)."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] * n[:, 0] * a, sign * b, -sign * n[:, 0]], -1)
    bt = np.stack([b, sign + n[:, 1] * n[:, 1] * a, -n[:, 1]], -1)
    return t, bt


def _strata(seed: int, ids: np.ndarray, rays: int, stream: int) -> tuple[np.ndarray, np.ndarray]:
    """Jittered ``s x s`` strata of the unit square per sample: ``(k, rays)`` each."""
    s = strata_side(rays)
    j = np.arange(rays, dtype=np.uint64)[None, :]
    a = np.asarray(ids, dtype=np.uint64)[:, None]
    cell = np.arange(rays)
    u1 = ((cell % s)[None, :] + hash_uniform(seed, a, j, stream)) / s
    u2 = ((cell // s)[None, :] + hash_uniform(seed, a, j, stream + 1)) / s
    return u1, u2


def cosine_directions(normals: npt.ArrayLike, ids: npt.ArrayLike, rays: int, seed: int = 0) -> np.ndarray:
    """Cosine-weighted directions about each normal, ``rays`` (``s x s`` strata) per point.

    Parameters
    ----------
    normals : (k, 3) float64 unit
    ids : (k,) int, each point's global sample index (the jitter's counter)
    rays : a square number

    Returns
    -------
    (k, rays, 3) float64 unit directions, all with ``d . n > 0``.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    u1, u2 = _strata(seed, np.asarray(ids), rays, 0)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    x, y, z = r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - u1, 1e-12))
    t, b = frame(n)
    return x[..., None] * t[:, None] + y[..., None] * b[:, None] + z[..., None] * n[:, None]


def disc_directions(axis: npt.ArrayLike, ids: npt.ArrayLike, rays: int, radius_deg: float, seed: int = 0, stream: int = 10) -> np.ndarray:
    """Directions to points of a disc of angular radius ``radius_deg`` about ``axis``: ``axis (k, 3)``
    unit (or (3,)), ``ids (k,)`` -> ``(k, rays, 3)`` unit (``s x s`` jittered strata mapped to the
    disc by the concentric map: uniform over the disc)."""
    ids = np.asarray(ids)
    ax = np.broadcast_to(np.asarray(axis, dtype=np.float64), (len(ids), 3))
    u1, u2 = _strata(seed, ids, rays, stream)
    a, b = 2.0 * u1 - 1.0, 2.0 * u2 - 1.0  # Shirley-Chiu concentric map
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, (np.pi / 4.0) * (b / np.where(a == 0, 1, a)),
                       (np.pi / 2.0) - (np.pi / 4.0) * (a / np.where(b == 0, 1, b)))
    x, y = r * np.cos(phi), r * np.sin(phi)
    t, bt = frame(ax)
    tan_r = math.tan(math.radians(radius_deg))
    d = ax[:, None] + tan_r * (x[..., None] * t[:, None] + y[..., None] * bt[:, None])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
