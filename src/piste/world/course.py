"""The default course: a seeded snowboard run on a mountain slope, as a Bézier patch net.

Layout (Z up, metres): the course spans ``x`` in ``[0, 400]`` (across) and ``y`` in ``[0, 1000]``
(down the fall line); the slope descends along +y from about 380 m to about 50 m.  It is built from
a procedural height field (``3.125 m`` samples) fitted by :func:`piste.terrain.fit.fit_heightfield`
into ``32 x 80 = 2,560`` patches of ``12.5 m``.

What is on it, all from ``numpy.random.default_rng(seed)``:

* a base slope whose steepness varies down the hill, plus smooth multi-octave undulations
  (a sum of random plane waves, wavelengths 35-260 m, a few metres high);
* a winding track: a gully that follows the centreline ``x = track_x(y)``, carved with a
  half-pipe-ish cross-section (a flat bottom ``12 m`` wide, smooth walls up to ``±16 m``, ``5 m``
  deep, small berms on the lips), with the undulations smoothed out inside it;
* kickers (jumps) and rollers along the track;
* rocky outcrops off the track (ridged bumps ``4-12 m`` high).

The built course is cached per seed; :func:`default_course` returns a fresh copy each call (cheap),
so callers may modify it.
"""

from __future__ import annotations

import copy
from functools import lru_cache

import numpy as np

# the height-field fit and the terrain query through the package's lazy names (PEP 562): used to make
# the default course, not by a render that only reads TRACK_HALF_WIDTH
from piste import terrain as _terrain
from piste.errors import ValidationError
from piste.terrain.net import PatchNet

__all__ = ["default_course", "track_centerline", "course_heightfield", "COURSE_WIDTH", "COURSE_LENGTH"]

COURSE_WIDTH = 400.0
COURSE_LENGTH = 1000.0
PATCH_SIZE = 12.5
SAMPLES_PER_PATCH = 4
SPACING = PATCH_SIZE / SAMPLES_PER_PATCH  # 3.125 m
TOP_HEIGHT = 380.0
DROP = 330.0
TRACK_HALF_FLAT = 6.0  # flat bottom half width
TRACK_HALF_WIDTH = 16.0  # wall tops
TRACK_DEPTH = 5.0


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    """Quintic smoothstep (C2), 0 below ``e0`` and 1 above ``e1``."""
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


class _Params:
    """Every random number of a course, drawn once from the seed (so the field is a pure function)."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.steep_phase = rng.uniform(0, 2 * np.pi)
        # track centreline: two sines
        self.track_l1 = rng.uniform(450.0, 650.0)
        self.track_l2 = rng.uniform(180.0, 240.0)
        self.track_p1 = rng.uniform(0, 2 * np.pi)
        self.track_p2 = rng.uniform(0, 2 * np.pi)
        self.track_a1 = rng.uniform(40.0, 55.0)
        self.track_a2 = rng.uniform(8.0, 14.0)
        # undulations: random plane waves
        m = 24
        wl = np.exp(rng.uniform(np.log(35.0), np.log(260.0), m))
        ang = rng.uniform(0, np.pi, m)
        self.wave_k = np.stack([np.cos(ang), np.sin(ang)], 1) * (2 * np.pi / wl)[:, None]
        self.wave_phase = rng.uniform(0, 2 * np.pi, m)
        self.wave_amp = 0.0065 * wl * rng.uniform(0.5, 1.0, m)
        # kickers along the track (y positions), rollers
        n_jumps = 6
        base = np.linspace(130.0, 880.0, n_jumps)
        self.jumps_y = base + rng.uniform(-35.0, 35.0, n_jumps)
        self.jumps_h = rng.uniform(1.6, 2.6, n_jumps)
        self.roller_l = rng.uniform(28.0, 40.0)
        self.roller_p = rng.uniform(0, 2 * np.pi)
        # rocky outcrops off the track
        rocks: list[tuple[float, ...]] = []
        while len(rocks) < 14:
            x, y = rng.uniform(20.0, COURSE_WIDTH - 20.0), rng.uniform(30.0, COURSE_LENGTH - 30.0)
            r, h = rng.uniform(6.0, 15.0), rng.uniform(4.0, 12.0)
            if abs(x - self.track_x(np.array([y]))[0]) > TRACK_HALF_WIDTH + r + 18.0:
                rocks.append((x, y, r, h, rng.uniform(0.15, 0.35), rng.uniform(0, 2 * np.pi)))
        self.rocks = np.array(rocks)

    def track_x(self, y: np.ndarray) -> np.ndarray:
        return (
            0.5 * COURSE_WIDTH
            + self.track_a1 * np.sin(2 * np.pi * y / self.track_l1 + self.track_p1)
            + self.track_a2 * np.sin(2 * np.pi * y / self.track_l2 + self.track_p2)
        )


def _field(p: _Params, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Course height at world ``(x, y)`` (broadcast arrays), float64."""
    g = y / COURSE_LENGTH + 0.035 * np.sin(2 * np.pi * 1.5 * y / COURSE_LENGTH + p.steep_phase)
    z = TOP_HEIGHT - DROP * g
    d = x - p.track_x(y)
    ad = np.abs(d)
    # a gully around the track, and a gentle bowl across the whole course
    z = z + 14.0 * (1.0 - np.exp(-((d / 45.0) ** 2))) + 20.0 * (1.0 - np.exp(-((d / 140.0) ** 2))) + 8.0 * ((x - 0.5 * COURSE_WIDTH) / (0.5 * COURSE_WIDTH)) ** 2
    # undulations, faded out inside the track
    phase = x[..., None] * p.wave_k[:, 0] + y[..., None] * p.wave_k[:, 1] + p.wave_phase
    waves = (p.wave_amp * np.sin(phase)).sum(-1)
    z = z + waves * _smoothstep(TRACK_HALF_FLAT, TRACK_HALF_WIDTH + 8.0, ad)
    # the half-pipe-ish channel and its berms
    inside = 1.0 - _smoothstep(TRACK_HALF_FLAT, TRACK_HALF_WIDTH, ad)
    z = z - TRACK_DEPTH * inside + 1.0 * np.exp(-(((ad - TRACK_HALF_WIDTH - 2.0) / 3.0) ** 2))
    # kickers (ramp up over 16 m, drop over 7 m) and rollers, inside the track only
    a = y[..., None] - p.jumps_y
    kick = (p.jumps_h * _smoothstep(-16.0, 0.0, a) * (1.0 - _smoothstep(0.0, 7.0, a))).sum(-1)
    rollers = 0.35 * np.sin(2 * np.pi * y / p.roller_l + p.roller_p)
    z = z + (kick + rollers) * (1.0 - _smoothstep(TRACK_HALF_FLAT, TRACK_HALF_WIDTH - 2.0, ad))
    # rocky outcrops: ridged bumps
    for rx, ry, rr, rh, rough, rp in p.rocks:  # 14 rocks, each a whole-field array operation
        q = ((x - rx) ** 2 + (y - ry) ** 2) / (rr * rr)
        bump = np.clip(1.0 - q, 0.0, None) ** 1.5
        ridge = 1.0 + rough * np.abs(np.sin(0.9 * (x - rx) + rp) + np.sin(0.7 * (y - ry) - rp))
        z = z + rh * bump * ridge
    return z


@lru_cache(maxsize=8)
def _params(seed: int) -> _Params:
    return _Params(seed)


def course_heightfield(seed: int = 0) -> tuple[np.ndarray, float, tuple[float, float]]:
    """The procedural height field of a course: ``(z (H, W) float64, spacing, origin)``.

    ``z[r, c]`` is the height at ``x = c * spacing``, ``y = r * spacing`` (``H = 321``, ``W = 129``).
    """
    p = _params(int(seed))
    nx = int(round(COURSE_WIDTH / SPACING)) + 1
    ny = int(round(COURSE_LENGTH / SPACING)) + 1
    y, x = np.meshgrid(np.arange(ny) * SPACING, np.arange(nx) * SPACING, indexing="ij")
    return _field(p, x, y), SPACING, (0.0, 0.0)


@lru_cache(maxsize=8)
def _course(seed: int) -> PatchNet:
    z, spacing, origin = course_heightfield(seed)
    net = _terrain.fit_heightfield(z, spacing, samples_per_patch=SAMPLES_PER_PATCH, origin=origin, name=f"default course (seed {seed})")
    return net


def default_course(seed: int = 0) -> PatchNet:
    """The default snowboard course for ``seed``: a :class:`piste.terrain.PatchNet` of 32 x 80 = 2,560
    patches (400 m x 1000 m, Z up, descending along +y).

    Deterministic: the same seed gives bit-identical control points.  Built once per seed and
    cached; each call returns an independent copy.  ``net.grid_shape == (80, 32)``: patch
    ``py * 32 + px`` covers ``x in [12.5 px, 12.5 (px+1)]``, ``y in [12.5 py, 12.5 (py+1)]``.
    """
    return copy.deepcopy(_course(int(seed)))


def track_centerline(seed: int = 0, n: int = 200) -> np.ndarray:
    """Points along the bottom of the track, on the exact surface, running downhill.

    Returns
    -------
    (n, 3) float64: ``x = track_x(y)``, ``y`` from 10 m to 990 m, ``z`` from :func:`piste.terrain.query.height_at`.
    """
    if int(n) < 2:
        raise ValidationError(f"track_centerline: n must be at least 2, got {n!r}")
    p = _params(int(seed))
    y = np.linspace(10.0, COURSE_LENGTH - 10.0, int(n))
    x = p.track_x(y)
    z, hit, _, _ = _terrain.height_at(_course(int(seed)), np.stack([x, y], 1))
    return np.stack([x, y, z], 1)
