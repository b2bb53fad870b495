"""Bone hierarchies: ordering, depth levels, local -> world matrices for all bones at once.

Functions here work on plain arrays so that :class:`piste.character.model.Skeleton` and other
code (compression, retargeting) share them.

- ``topological_order(parents) -> (b,) int``: an order in which parents come before children.
- ``depth_levels(parents) -> list[(n_i,) int]``: bone indices grouped by depth (roots first).
- ``world_from_local(local, parents, levels) -> (..., b, 4, 4)``: one batched matmul per level.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from piste.errors import ValidationError

__all__ = ["topological_order", "depth_levels", "world_from_local", "bone_depths"]


def bone_depths(parents: npt.ArrayLike) -> np.ndarray:
    """Depth of each bone ``(b,) int32`` (roots 0). Raises ValidationError on cycles."""
    parents = np.asarray(parents, dtype=np.int64)
    b = parents.shape[0]
    depth = np.zeros(b, dtype=np.int32)
    cur = parents.copy()
    for _ in range(b + 1):
        has = cur >= 0
        if not has.any():
            return depth
        depth[has] += 1
        cur = np.where(has, parents[np.maximum(cur, 0)], -1)
    raise ValidationError("bone hierarchy has a cycle (a bone is its own ancestor)")


def topological_order(parents: np.ndarray) -> np.ndarray:
    """Permutation ``(b,) int64`` listing bones so that every parent precedes its children.

    Stable: bones of equal depth keep their relative order.
    """
    return np.argsort(bone_depths(parents), kind="stable")


def depth_levels(parents: np.ndarray) -> list[np.ndarray]:
    """Bone indices per depth level, ``[(n_0,), (n_1,), ...] int64``, roots first."""
    d = bone_depths(parents)
    if d.size == 0:
        return []
    return [np.flatnonzero(d == k) for k in range(int(d.max()) + 1)]


def world_from_local(local: npt.ArrayLike, parents: npt.ArrayLike, levels: list[np.ndarray] | None = None) -> np.ndarray:
    """World matrices ``(..., b, 4, 4)`` from local matrices ``(..., b, 4, 4)``.

    ``world[i] = world[parents[i]] @ local[i]`` for all bones of one depth level in one batched
    matmul; roots (parent -1) keep their local matrix. Leading batch dimensions (e.g. several
    poses) are supported.
    """
    local = np.asarray(local, dtype=np.float64)
    parents = np.asarray(parents)
    if levels is None:
        levels = depth_levels(parents)
    world = local.copy()
    for lvl in levels[1:]:
        world[..., lvl, :, :] = world[..., parents[lvl], :, :] @ local[..., lvl, :, :]
    return world
