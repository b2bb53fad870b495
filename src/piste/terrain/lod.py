"""Per-edge distance LOD and view-frustum culling of patches.

The talk: "Distance based heuristic applied to each edge, evaluated to 4, 6 or 8 vertices per
edge".  The level is a function of the edge alone (its midpoint's distance to the eye), so the
two patches on a shared edge always agree: crack-freedom needs nothing more.
"""

from __future__ import annotations

import numpy as np

from piste.errors import ConfigError
from piste.transforms import cull_boxes, frustum_planes, look_at, perspective

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


def visible_patches(net, eye, target, fov_y: float = 60.0, aspect: float = 640 / 448, znear: float = 0.5,
                    zfar: float = 5000.0, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Patches whose control-point bounds intersect the view frustum, ``(p,)`` int64."""
    planes = frustum_planes(perspective(fov_y, aspect, znear, zfar) @ look_at(eye, target, up))
    lo, hi = net.patch_bounds
    return np.nonzero(cull_boxes(((lo + hi) / 2).T, ((hi - lo) / 2).T, planes))[0]
