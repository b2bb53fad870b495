"""An area sun in the light-map bake (issue 27 item 5, bake side): ``sun_radius`` degrees, shadow
rays to stratified points of the sun's disc, against a ray-traced area-light reference with many
more rays per sample."""

from __future__ import annotations

import numpy as np
import pytest
from lighting_nets import wall_scene

from piste.lighting import AmbientLight, DirectionalLight, Lights, bake_lightmap, light_terms, sample_points
from piste.lighting.gi import REAL_SUN_RADIUS
from piste.lighting.sampling import disc_directions
from piste.lighting.shadows import shadow_visibility

RES = 16
SUN = DirectionalLight((0.62, 0.07, -0.7), (1.0, 0.95, 0.85), 1.0, name="sun")  # edges between samples


@pytest.fixture(scope="module")
def scene():
    net = wall_scene()  # a 10 m wall at x = 20 facing +x: its shadow falls on the ground beyond it
    lights = Lights((AmbientLight((0.3, 0.35, 0.45), 0.5), SUN))
    pos, nrm = sample_points(net, RES)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    return net, lights, pos, nrm, light_terms(lights, pos, nrm)


def _vis(scene, where=None, **kw):
    net, lights, pos, nrm, terms = scene
    if where is None:
        where = np.arange(len(pos))
    ids = np.arange(len(pos))[where]
    return shadow_visibility(net, lights, pos[where], nrm[where], terms[where], ids=ids, **kw)[:, 0]


def test_penumbra_against_the_area_light_reference(scene):
    radius = 2.0
    # the reference (32 x 32 strata, other jitter) where a wider sun's penumbra is: a superset of
    # this one's (everything else is fully lit or fully shadowed under both)
    wider = _vis(scene, sun_radius=1.5 * radius, sun_rays=64, seed=7, sun_adaptive=False)
    cand = np.flatnonzero((wider > 0.0) & (wider < 1.0))
    ref = np.where(wider >= 1.0, 1.0, 0.0)
    ref[cand] = _vis(scene, cand, sun_radius=radius, sun_rays=1024, seed=99, sun_adaptive=False)
    pen = (ref > 0.02) & (ref < 0.98)
    assert pen.sum() >= 30  # the test sees a real penumbra
    soft = _vis(scene, sun_radius=radius)  # 64 rays, the rim's 8 first
    full = _vis(scene, sun_radius=radius, sun_adaptive=False)  # all 64 everywhere
    few = _vis(scene, sun_radius=radius, sun_rays=16, sun_adaptive=False)
    hard = _vis(scene)
    err_soft = np.abs(soft - ref)[pen].mean()
    err_full = np.abs(full - ref)[pen].mean()
    err_hard = np.abs(hard - ref)[pen].mean()
    assert err_soft < 0.03, err_soft
    assert err_soft <= 1.05 * err_full + 1e-3  # the rim rays find the penumbra
    assert np.abs(few - ref)[pen].mean() > err_soft  # more rays, less error
    assert err_hard > 0.2 and err_hard > 6 * err_soft
    # outside the penumbra the area sun agrees with the hard one (fully lit or fully shadowed)
    far = (ref == 0.0) | (ref == 1.0)
    assert np.abs(soft - hard)[far].mean() < 0.01
    assert set(np.unique(np.round(soft * 64, 9))) <= set(range(65))  # fractions of 64 rays


def test_penumbra_width_follows_the_radius(scene):
    pos = scene[2]
    behind = np.flatnonzero((np.abs(pos[:, 2]) < 1e-9) & (pos[:, 0] > 20.5))  # the ground the wall shades
    narrow = _vis(scene, behind, sun_radius=REAL_SUN_RADIUS, sun_rays=64)
    wide = _vis(scene, behind, sun_radius=3.0, sun_rays=64)
    count = lambda v: int(((v > 0.0) & (v < 1.0)).sum())  # noqa: E731
    assert 0 < count(narrow) < count(wide) / 3, (count(narrow), count(wide))


def test_hard_sun_is_unchanged_and_soft_bake_differs_only_at_the_edges(scene):
    net, lights, *_ = scene
    plain = bake_lightmap(net, lights, res=RES)
    zero = bake_lightmap(net, lights, res=RES, sun_radius=0.0)
    assert np.array_equal(plain.atlas, zero.atlas) and plain.manifest == zero.manifest
    soft = bake_lightmap(net, lights, res=RES, sun_radius=2.0)
    assert soft.manifest["gi"] == {"sun_radius": 2.0, "sun_rays": 64, "seed": 0}
    # eight rim rays per lit sample, all 64 in the penumbra only
    assert 8 * plain.stats["rays"] < soft.stats["rays"] < 12 * plain.stats["rays"]
    d = np.abs(soft.tiles() - plain.tiles()).max(-1)
    assert d.max() > 0.2  # a penumbra
    assert (d > 1e-6).mean() < 0.25  # ... at the shadow's edges only


def test_disc_directions_stay_on_the_disc():
    axis = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    d = disc_directions(axis, np.arange(2), 64, 2.0, seed=5)
    ang = np.degrees(np.arccos(np.clip(np.einsum("krc,kc->kr", d, axis), -1, 1)))
    assert ang.max() <= 2.0 + 1e-9 and ang.min() >= 0.0
    # uniform over the disc: half the rays within radius / sqrt(2) (tangent plane), stratified
    assert abs((np.tan(np.radians(ang)) < np.tan(np.radians(2.0)) / np.sqrt(2)).mean() - 0.5) < 0.1
    assert np.array_equal(disc_directions(axis[1:], np.arange(1, 2), 64, 2.0, seed=5), d[1:])
