"""Sampling animation tracks and clips (glTF semantics), and retargeting by bone name.

- ``sample_track(track, t, rotation=False) -> (c,)``: STEP, LINEAR (slerp for rotations) and
  CUBICSPLINE (glTF 2.0 Appendix C Hermite form, tangents scaled by the key interval; rotations
  normalised afterwards). ``t`` is clamped to the track's key range.
- ``sample_track_many(track, times) -> (m, c)``: the same for many times at once (vectorised).
- ``clip_time(t, duration, loop)``: clamp to ``[0, duration]`` or wrap.
- ``sample_pose(clip, t, target, source, retarget) -> Pose``: see :mod:`piste.character.model`
  for the retarget rule.
- ``sample_poses(clip, times, target) -> (translation (m, b, 3), rotation (m, b, 4), scale (m, b, 3))``:
  the poses at many (already clamped) times at once, without retargeting (the clip's own skeleton):
  one vectorised call per track instead of one per track and time.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError
from piste.transforms import quat_conjugate, quat_multiply, quat_normalize, quat_slerp

__all__ = ["sample_track", "sample_track_many", "clip_time", "sample_pose", "sample_poses", "RETARGET_MODES"]

RETARGET_MODES = ("none", "scaled", "relative")

# ``track``, ``clip``, ``target``/``source`` and the returned pose are piste.character.model's Track,
# Clip, Skeleton and Pose, typed Any here: model.py imports this module (an import back is a cycle)


def clip_time(t: float, duration: float, loop: bool) -> float:
    """Clamp ``t`` to ``[0, duration]``, or wrap it into ``[0, duration)`` when ``loop``."""
    t = float(t)
    if duration <= 0:
        return 0.0
    if loop:
        return t % duration
    return min(max(t, 0.0), duration)


def sample_track_many(track: Any, times: npt.ArrayLike, rotation: bool = False) -> np.ndarray:
    """Values ``(m, c) float64`` of ``track`` at ``times (m,)`` (clamped to the key range)."""
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    kt = track.times
    vals = track.values
    n = kt.shape[0]
    if n == 1:
        out = np.repeat(vals[:1], times.shape[0], axis=0)
        return quat_normalize(out) if rotation else out
    t = np.clip(times, kt[0], kt[-1])
    i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, n - 2)
    t0 = kt[i]
    t1 = kt[i + 1]
    dt = t1 - t0
    u = np.where(dt > 0, (t - t0) / np.where(dt > 0, dt, 1.0), 0.0)
    interp = track.interpolation
    if interp == "STEP":
        return np.where((t >= t1)[:, None], vals[i + 1], vals[i])
    if interp == "CUBICSPLINE":
        u2 = u * u
        u3 = u2 * u
        h00 = 2 * u3 - 3 * u2 + 1
        h10 = u3 - 2 * u2 + u
        h01 = -2 * u3 + 3 * u2
        h11 = u3 - u2
        d = dt[:, None]
        out = (h00[:, None] * vals[i] + h10[:, None] * d * track.out_tangents[i]
               + h01[:, None] * vals[i + 1] + h11[:, None] * d * track.in_tangents[i + 1])
        return quat_normalize(out) if rotation else out
    if rotation:
        return quat_slerp(vals[i], vals[i + 1], u)
    return vals[i] + u[:, None] * (vals[i + 1] - vals[i])


def sample_track(track: Any, t: float, rotation: bool = False) -> np.ndarray:
    """Value ``(c,) float64`` of ``track`` at time ``t`` (clamped to the key range)."""
    return sample_track_many(track, [t], rotation=rotation)[0]


def _gather(clip: Any, t: float, target: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Sampled clip values on the bones of ``target``: three dicts path -> (bone idx, values)."""
    out = {}
    for path in ("translation", "rotation", "scale"):
        idx, vals = [], []
        for name, bt in clip.tracks.items():
            tr = bt.get(path)
            if tr is None:
                continue
            j = target.get(name)
            if j is None:
                continue
            idx.append(j)
            vals.append(sample_track(tr, t, rotation=(path == "rotation")))
        c = 4 if path == "rotation" else 3
        out[path] = (np.asarray(idx, dtype=np.int64), np.asarray(vals, dtype=np.float64).reshape(-1, c))
    return out


def sample_poses(clip: Any, times: npt.ArrayLike, target: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The poses of ``target`` at ``times (m,)`` (already clamped or wrapped), as
    :func:`sample_pose` with ``retarget="none"`` gives them one at a time: ``translation (m, b, 3)``,
    ``rotation (m, b, 4)`` xyzw, ``scale (m, b, 3)`` float64; bones without tracks keep the rest
    values."""
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    rest = target.rest_pose()
    m = times.shape[0]
    out = {path: np.repeat(np.asarray(getattr(rest, path), dtype=np.float64)[None], m, axis=0)
           for path in ("translation", "rotation", "scale")}
    for name, bt in clip.tracks.items():
        j = target.get(name)
        if j is None:
            continue
        for path in ("translation", "rotation", "scale"):
            tr = bt.get(path)
            if tr is not None:
                out[path][:, j] = sample_track_many(tr, times, rotation=(path == "rotation"))
    return out["translation"], out["rotation"], out["scale"]


def sample_pose(clip: Any, t: float, target: Any, source: Any = None, retarget: str = "none") -> Any:
    """Pose of ``target`` at clip time ``t`` (already clamped/wrapped).

    ``source`` is the skeleton the clip was made for (or None); ``retarget`` one of
    ``RETARGET_MODES`` (see :mod:`piste.character.model`).
    """
    if retarget not in RETARGET_MODES:
        raise ConfigError(f"retarget must be one of {RETARGET_MODES}, got {retarget!r}")
    pose = target.rest_pose()
    g = _gather(clip, t, target)
    if retarget == "none" or source is None or source is target:
        for path in ("translation", "rotation", "scale"):
            idx, vals = g[path]
            getattr(pose, path)[idx] = vals
        return pose

    def src_index(idx: np.ndarray) -> np.ndarray:
        names = [target.names[j] for j in idx]
        return np.array([source.get(n, -1) for n in names], dtype=np.int64)

    # translation
    idx, vals = g["translation"]
    if idx.size:
        si = src_index(idx)
        have = si >= 0
        s_rest = np.where(have[:, None], source.rest_translation[np.maximum(si, 0)], target.rest_translation[idx])
        t_rest = target.rest_translation[idx]
        ls = np.linalg.norm(s_rest, axis=1)
        lt = np.linalg.norm(t_rest, axis=1)
        ratio = np.where(ls > 1e-12, lt / np.where(ls > 1e-12, ls, 1.0), 1.0)
        if retarget == "scaled":
            pose.translation[idx] = vals * ratio[:, None]
        else:
            pose.translation[idx] = t_rest + ratio[:, None] * (vals - s_rest)
    # rotation
    idx, vals = g["rotation"]
    if idx.size:
        if retarget == "scaled":
            pose.rotation[idx] = vals
        else:
            si = src_index(idx)
            have = si >= 0
            s_rest = np.where(have[:, None], source.rest_rotation[np.maximum(si, 0)], target.rest_rotation[idx])
            delta = quat_multiply(quat_conjugate(s_rest), vals)
            pose.rotation[idx] = quat_normalize(quat_multiply(target.rest_rotation[idx], delta))
    # scale
    idx, vals = g["scale"]
    if idx.size:
        if retarget == "scaled":
            pose.scale[idx] = vals
        else:
            si = src_index(idx)
            have = si >= 0
            s_rest = np.where(have[:, None], source.rest_scale[np.maximum(si, 0)], target.rest_scale[idx])
            safe = np.where(np.abs(s_rest) > 1e-12, s_rest, 1.0)
            pose.scale[idx] = target.rest_scale[idx] * vals / safe
    return pose
