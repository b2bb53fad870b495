"""Per-edge distance LOD and view-frustum culling of patches.

The talk: "Distance based heuristic applied to each edge, evaluated to 4, 6 or 8 vertices per
edge".  The level is a function of the edge alone (its midpoint's distance to the eye), so the
two patches on a shared edge always agree: crack-freedom needs nothing more.
"""

from __future__ import annotations

import numpy as np

from piste.errors import ConfigError

#: default thresholds for a course in metres: edges nearer than ``near`` get 8 vertices, nearer
#: than ``far`` 6, the rest 4 (tuned so a view down the default course gives the talk's mix)
DEFAULT_NEAR = 60.0
DEFAULT_FAR = 180.0
LEVELS = (4, 6, 8)


def edge_levels(net, eye, near: float = DEFAULT_NEAR, far: float = DEFAULT_FAR, levels=LEVELS) -> np.ndarray:
    """Vertices per edge for a camera at ``eye``.

    Parameters
    ----------
    net : PatchNet
    eye : (3,) camera position
    near, far : distance thresholds (model units): ``d < near`` -> ``levels[2]``,
        ``d < far`` -> ``levels[1]``, else ``levels[0]``
    levels : (coarse, medium, fine) vertices per edge

    Returns
    -------
    (e,) int16, one level per edge of ``net`` (collapsed edges get the coarse level).
    """
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(eye)):
        raise ConfigError(f"eye must be finite, got {eye.tolist()}")
    if not (0 <= near <= far):
        raise ConfigError(f"LOD thresholds must satisfy 0 <= near <= far, got near={near}, far={far}")
    if len(levels) != 3:
        raise ConfigError(f"levels must be (coarse, medium, fine), got {levels}")
    d = np.linalg.norm(net.edge_midpoints() - eye, axis=1)
    out = np.where(d < near, levels[2], np.where(d < far, levels[1], levels[0])).astype(np.int16)
    out[net.edge_degenerate] = levels[0]
    return out


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Right-handed view matrix (camera looks down -z), ``(4, 4)`` float64, column vectors."""
    eye, target, up = (np.asarray(x, dtype=np.float64) for x in (eye, target, up))
    f = target - eye
    fn = np.linalg.norm(f)
    if fn == 0:
        raise ConfigError("camera eye and target coincide")
    f /= fn
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:  # looking straight along up
        s = np.cross(f, (0.0, 1.0, 0.0))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, znear: float, zfar: float) -> np.ndarray:
    """OpenGL perspective projection, ``(4, 4)`` float64."""
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (zfar + znear) / (znear - zfar)
    m[2, 3] = 2.0 * zfar * znear / (znear - zfar)
    m[3, 2] = -1.0
    return m


def frustum_planes(view_proj: np.ndarray) -> np.ndarray:
    """The six planes ``(a, b, c, d)`` (inside: ``a x + b y + c z + d >= 0``) of a view-projection
    matrix, ``(6, 4)`` float64 (Gribb-Hartmann)."""
    m = np.asarray(view_proj, dtype=np.float64)
    return np.stack([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]])


def cull_boxes(lo: np.ndarray, hi: np.ndarray, view_proj: np.ndarray) -> np.ndarray:
    """Which axis-aligned boxes intersect (or may intersect) the frustum.

    Parameters
    ----------
    lo, hi : (n, 3) box corners
    view_proj : (4, 4) projection @ view

    Returns
    -------
    (n,) bool, conservative (a box is culled only if it is fully outside one plane).
    """
    planes = frustum_planes(view_proj)
    normal = planes[:, :3]
    # the box corner furthest along each plane normal
    pos = np.where(normal[None] >= 0, hi[:, None, :], lo[:, None, :])  # (n, 6, 3)
    dist = np.einsum("npk,pk->np", pos, normal) + planes[:, 3]
    return (dist >= 0).all(axis=1)


def visible_patches(net, eye, target, fov_y: float = 60.0, aspect: float = 640 / 448, znear: float = 0.5,
                    zfar: float = 5000.0, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Patches whose control-point bounds intersect the view frustum, ``(p,)`` int64."""
    vp = perspective(fov_y, aspect, znear, zfar) @ look_at(eye, target, up)
    lo, hi = net.patch_bounds
    return np.nonzero(cull_boxes(lo, hi, vp))[0]
