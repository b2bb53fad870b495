"""Batched quaternions and 4x4 affine matrices (pure numpy).

Conventions
-----------
- Quaternions are ``(..., 4)`` arrays in glTF order ``(x, y, z, w)``.
- Matrices use the column-vector convention: ``p_world = M @ [x, y, z, 1]``; the translation is
  ``M[..., :3, 3]``.
- Every function broadcasts over leading dimensions and never loops in Python over elements.

API
---
quat_normalize, quat_multiply, quat_conjugate, quat_rotate, quat_slerp, quat_nlerp,
quat_to_matrix, matrix_to_quat, quat_identity, quat_angle,
compose_trs, decompose_trs, invert_affine, transform_points, transform_vectors, translation_matrix
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError

__all__ = [
    "quat_identity",
    "quat_normalize",
    "quat_multiply",
    "quat_conjugate",
    "quat_rotate",
    "quat_slerp",
    "quat_nlerp",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_angle",
    "compose_trs",
    "decompose_trs",
    "invert_affine",
    "transform_points",
    "transform_vectors",
    "translation_matrix",
    "look_at",
    "perspective",
    "orthographic",
    "frustum_planes",
    "cull_boxes",
]


def quat_identity(shape: int | tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions ``(*shape, 4) float64`` = (0, 0, 0, 1)."""
    shape = (shape,) if isinstance(shape, (int, np.integer)) else tuple(shape)
    q = np.zeros(shape + (4,), dtype=np.float64)
    q[..., 3] = 1.0
    return q


def quat_normalize(q: npt.ArrayLike) -> np.ndarray:
    """Unit quaternions ``(..., 4)``; zero quaternions become the identity."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.divide(q, n, out=np.zeros_like(q), where=n > 0)
    zero = (n[..., 0] == 0)
    if np.any(zero):
        out[zero] = (0.0, 0.0, 0.0, 1.0)
    return out


def quat_multiply(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """Hamilton product ``a * b`` ``(..., 4)`` (applies ``b`` first, then ``a``)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_conjugate(q: npt.ArrayLike) -> np.ndarray:
    """Conjugate (= inverse for unit quaternions) ``(..., 4)``."""
    q = np.array(q, dtype=np.float64, copy=True)
    q[..., :3] *= -1.0
    return q


def quat_rotate(q: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_angle(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """Rotation angle in radians ``(...,)`` between unit quaternions ``a`` and ``b``."""
    d = np.abs(np.sum(np.asarray(a, np.float64) * np.asarray(b, np.float64), axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def quat_nlerp(a: npt.ArrayLike, b: npt.ArrayLike, t: npt.ArrayLike) -> np.ndarray:
    """Normalised linear interpolation along the shortest arc; ``t`` broadcasts as ``(...,)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    return quat_normalize(a * (1.0 - t) + b * sign * t)


def quat_slerp(a: npt.ArrayLike, b: npt.ArrayLike, t: npt.ArrayLike) -> np.ndarray:
    """Spherical linear interpolation along the shortest arc.

    ``a, b (..., 4)`` unit quaternions, ``t`` broadcastable to ``(...,)``. Falls back to nlerp for
    nearly parallel inputs. Returns ``(..., 4) float64``.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0.0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-6
    safe_s = np.where(small, 1.0, s)
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / safe_s)
    wb = np.where(small, t, np.sin(t * theta) / safe_s)
    return quat_normalize(wa * a + wb * b)


def quat_to_matrix(q: npt.ArrayLike) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3) float64`` of quaternions ``(..., 4)`` (normalised first)."""
    q = quat_normalize(q)
    x, y, z, w = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty(q.shape[:-1] + (3, 3), dtype=np.float64)
    m[..., 0, 0] = 1 - 2 * (yy + zz)
    m[..., 0, 1] = 2 * (xy - wz)
    m[..., 0, 2] = 2 * (xz + wy)
    m[..., 1, 0] = 2 * (xy + wz)
    m[..., 1, 1] = 1 - 2 * (xx + zz)
    m[..., 1, 2] = 2 * (yz - wx)
    m[..., 2, 0] = 2 * (xz - wy)
    m[..., 2, 1] = 2 * (yz + wx)
    m[..., 2, 2] = 1 - 2 * (xx + yy)
    return m


def matrix_to_quat(m: npt.ArrayLike) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` (w >= 0) of rotation matrices ``(..., 3, 3)`` (or 4x4).

    Uses the numerically stable branch on the largest of (trace, diagonal) per matrix, vectorised.
    """
    m = np.asarray(m, dtype=np.float64)[..., :3, :3]
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,), dtype=np.float64)
    # branch w
    s = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2.0
    qw = np.stack([(m[..., 2, 1] - m[..., 1, 2]) / s, (m[..., 0, 2] - m[..., 2, 0]) / s,
                   (m[..., 1, 0] - m[..., 0, 1]) / s, 0.25 * s], axis=-1)
    s = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2.0
    qx = np.stack([0.25 * s, (m[..., 0, 1] + m[..., 1, 0]) / s, (m[..., 0, 2] + m[..., 2, 0]) / s,
                   (m[..., 2, 1] - m[..., 1, 2]) / s], axis=-1)
    s = np.sqrt(np.maximum(1.0 - m00 + m11 - m22, 1e-300)) * 2.0
    qy = np.stack([(m[..., 0, 1] + m[..., 1, 0]) / s, 0.25 * s, (m[..., 1, 2] + m[..., 2, 1]) / s,
                   (m[..., 0, 2] - m[..., 2, 0]) / s], axis=-1)
    s = np.sqrt(np.maximum(1.0 - m00 - m11 + m22, 1e-300)) * 2.0
    qz = np.stack([(m[..., 0, 2] + m[..., 2, 0]) / s, (m[..., 1, 2] + m[..., 2, 1]) / s, 0.25 * s,
                   (m[..., 1, 0] - m[..., 0, 1]) / s], axis=-1)
    kk = k[..., None]
    q = np.where(kk == 0, qw, np.where(kk == 1, qx, np.where(kk == 2, qy, qz)))
    q = np.where(q[..., 3:4] < 0, -q, q)
    return quat_normalize(q)



def look_rotation(forward: npt.ArrayLike, up: npt.ArrayLike, fallback: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> list[float]:
    """Rotation ``[x, y, z, w]`` (unit) whose -Z axis is ``forward`` and +Y is (nearly) ``up``: the
    orientation glTF gives cameras and lights.  Where ``forward`` is parallel to ``up``, the right
    axis comes from ``forward`` x ``fallback`` instead (or x +X when ``forward`` is near +-X)."""
    f = np.asarray(forward, dtype=np.float64)
    f = f / max(float(np.linalg.norm(f)), 1e-300)
    r = np.cross(f, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(r) < 1e-9:
        r = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else list(fallback))
    r = r / np.linalg.norm(r)
    m = np.eye(3)
    m[:, 0], m[:, 1], m[:, 2] = r, np.cross(r, f), -f
    q = matrix_to_quat(m)
    return [float(x) for x in q / np.linalg.norm(q)]

def translation_matrix(t: npt.ArrayLike) -> np.ndarray:
    """``(..., 4, 4)`` translation matrices of ``t (..., 3)``."""
    t = np.asarray(t, dtype=np.float64)
    m = np.zeros(t.shape[:-1] + (4, 4), dtype=np.float64)
    m[..., 0, 0] = m[..., 1, 1] = m[..., 2, 2] = m[..., 3, 3] = 1.0
    m[..., :3, 3] = t
    return m


def compose_trs(t: npt.ArrayLike, r: npt.ArrayLike, s: npt.ArrayLike) -> np.ndarray:
    """``T @ R @ S`` as ``(..., 4, 4) float64`` from ``t (..., 3)``, ``r (..., 4)`` xyzw, ``s (..., 3)``."""
    t = np.asarray(t, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    rm = quat_to_matrix(r)
    shape = np.broadcast_shapes(t.shape[:-1], rm.shape[:-2], s.shape[:-1])
    m = np.zeros(shape + (4, 4), dtype=np.float64)
    m[..., :3, :3] = rm * s[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


def decompose_trs(m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split affine matrices ``(..., 4, 4)`` into ``(t (...,3), r (...,4) xyzw, s (...,3))``.

    Shear is dropped; a negative determinant flips the sign of the x scale.
    """
    m = np.asarray(m, dtype=np.float64)
    t = m[..., :3, 3].copy()
    a = m[..., :3, :3]
    s = np.linalg.norm(a, axis=-2)
    det = np.linalg.det(a)
    s[..., 0] = np.where(det < 0, -s[..., 0], s[..., 0])
    safe = np.where(np.abs(s) > 1e-300, s, 1.0)
    r = matrix_to_quat(a / safe[..., None, :])
    return t, r, s


def invert_affine(m: npt.ArrayLike) -> np.ndarray:
    """Inverse of affine matrices ``(..., 4, 4)`` (general 3x3 part, last row 0 0 0 1)."""
    m = np.asarray(m, dtype=np.float64)
    a = np.linalg.inv(m[..., :3, :3])
    out = np.zeros_like(m)
    out[..., :3, :3] = a
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", a, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def transform_points(m: npt.ArrayLike, p: npt.ArrayLike) -> np.ndarray:
    """Apply ``m (4, 4)`` (or ``(..., 4, 4)`` broadcasting against ``p``) to points ``p (..., 3)``."""
    m = np.asarray(m)
    p = np.asarray(p)
    if m.ndim == 2:
        return p @ m[:3, :3].T + m[:3, 3]
    return np.einsum("...ij,...j->...i", m[..., :3, :3], p) + m[..., :3, 3]


def transform_vectors(m: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray:
    """Apply the 3x3 part of ``m`` to direction vectors ``v (..., 3)`` (no translation)."""
    m = np.asarray(m)
    v = np.asarray(v)
    if m.ndim == 2:
        return v @ m[:3, :3].T
    return np.einsum("...ij,...j->...i", m[..., :3, :3], v)


# ------------------------------------------------------------------ cameras and frusta
def look_at(eye: npt.ArrayLike, target: npt.ArrayLike, up: npt.ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """View matrix ``(4, 4) float64`` of a camera at ``eye`` looking at ``target``."""
    eye = np.asarray(eye, dtype=np.float64)
    f = np.asarray(target, dtype=np.float64) - eye
    fn = np.linalg.norm(f)
    if not fn > 0:
        raise ConfigError(f"camera: eye {eye.tolist()} and target are the same point")
    f = f / fn
    up = np.asarray(up, dtype=np.float64)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:  # looking straight along up: pick any side vector
        s = np.cross(f, np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.9 else np.array([1.0, 0.0, 0.0]))
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection ``(4, 4) float64`` (vertical field of view in degrees)."""
    if not (0 < near < far):
        raise ConfigError(f"camera: need 0 < near < far, got near={near}, far={far}")
    if not (0 < fov_y_deg < 180):
        raise ConfigError(f"camera: fov_y must be in (0, 180) degrees, got {fov_y_deg}")
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """OpenGL orthographic projection ``(4, 4) float64``."""
    m = np.eye(4)
    m[0, 0] = 2.0 / (right - left)
    m[1, 1] = 2.0 / (top - bottom)
    m[2, 2] = -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


def frustum_planes(view_projection: npt.ArrayLike) -> np.ndarray:
    """The six planes (left, right, bottom, top, near, far) of a view frustum.

    Returns ``(6, 4) float64`` rows ``(a, b, c, d)`` with unit normals pointing into the frustum:
    a point ``p`` is inside when ``a*x + b*y + c*z + d >= 0`` for all six.
    """
    m = np.asarray(view_projection, dtype=np.float64)
    r0, r1, r2, r3 = m
    planes = np.stack([r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 + r2, r3 - r2])
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


def cull_boxes(centre: np.ndarray, half: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Which boxes meet a frustum (conservative: a box is dropped only when it lies wholly outside
    one plane).

    Parameters
    ----------
    centre, half : (3, n) float64 box centres and half extents (coordinate-major for two GEMVs)
    planes : (6, 4) float64 inward planes (:func:`frustum_planes`)

    Returns
    -------
    (n,) bool
    """
    dist = planes[:, :3] @ centre + planes[:, 3:4]  # (6, n) signed distance of the centres
    reach = np.abs(planes[:, :3]) @ half  # (6, n) the boxes' extent along each normal
    return (dist + reach >= 0.0).all(axis=0)
