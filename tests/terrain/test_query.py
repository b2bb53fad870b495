"""Exact-surface queries: height_at and ray_intersect against analytic surfaces and dense sampling."""

import numpy as np
import pytest

from piste.errors import ValidationError
from piste.terrain import PatchNet, fit_heightfield, height_at, ray_intersect
from piste.terrain.bezier import evaluate
from piste.terrain.query import PatchBVH, clear_cache, eval_points

from nets import TEAPOT  # noqa: E402

# x^2 on [-1, 1] as a cubic Bézier (degree-elevated [1, -1, 1]); x itself: [-1, -1/3, 1/3, 1]
_SQ = np.array([1.0, -1.0 / 3.0, -1.0 / 3.0, 1.0])
_LIN = np.array([-1.0, -1.0 / 3.0, 1.0 / 3.0, 1.0])


def paraboloid_net(a=0.5, offset=(0.0, 0.0)):
    """One patch exactly equal to z = a (x^2 + y^2) over [-1, 1]^2 (shifted by ``offset``)."""
    cp = np.empty((1, 4, 4, 3))
    cp[0, :, :, 0] = _LIN[:, None] + offset[0]
    cp[0, :, :, 1] = _LIN[None, :] + offset[1]
    cp[0, :, :, 2] = a * (_SQ[:, None] + _SQ[None, :])
    return PatchNet(cp, name="paraboloid")


def flat_net(n=3, size=2.0, z=1.0):
    """n x n flat patches at height z (the plane z = const, u along x, v along y)."""
    t = np.arange(4) / 3.0
    px, py = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    cp = np.empty((n * n, 4, 4, 3))
    cp[..., 0] = (px.ravel()[:, None, None] + t[None, :, None]) * size
    cp[..., 1] = (py.ravel()[:, None, None] + t[None, None, :]) * size
    cp[..., 2] = z
    return PatchNet(cp, name="flat")


def bumpy_net(seed=1, n=6):
    """A small C0 net fitted to a smooth random field with some relief (10 m patches)."""
    rng = np.random.default_rng(seed)
    h = w = 4 * n + 1
    y, x = np.mgrid[0:h, 0:w] * 2.5
    z = np.zeros((h, w))
    for _ in range(8):
        k = rng.normal(size=2) * 0.15
        z += rng.uniform(0.5, 3.0) * np.sin(k[0] * x + k[1] * y + rng.uniform(0, 6.3))
    z += 0.2 * y
    return fit_heightfield(z, 2.5, name="bumpy")


def dense_mesh(net, m=33):
    """Triangles of a dense uniform sampling of every patch: (t, 3, 3)."""
    t = np.linspace(0.0, 1.0, m)
    v, u = np.meshgrid(t, t, indexing="ij")
    pos = evaluate(net.control_points, u.ravel(), v.ravel(), normals=False).reshape(len(net), m, m, 3)
    a, b, c, d = pos[:, :-1, :-1], pos[:, :-1, 1:], pos[:, 1:, 1:], pos[:, 1:, :-1]
    tri = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    return tri


def brute_rays(tri, o, d, chunk=64):
    """Nearest Möller-Trumbore hit of each ray against all triangles: t (k,), inf for misses."""
    out = np.full(len(o), np.inf)
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    for s in range(0, len(o), chunk):
        oo, dd = o[s : s + chunk, None], d[s : s + chunk, None]
        p = np.cross(dd, e2)
        det = np.einsum("rtc,tc->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = oo - v0
            uu = np.einsum("rtc,rtc->rt", tv, p) * inv
            q = np.cross(tv, e1)
            vv = np.einsum("rtc,rtc->rt", dd, q) * inv
            tt = np.einsum("tc,rtc->rt", e2, q) * inv
        ok = (np.abs(det) > 1e-14) & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt > 1e-9)
        out[s : s + chunk] = np.where(ok, tt, np.inf).min(1)
    return out


# --------------------------------------------------------------------------- height_at
def test_height_at_reproduces_cubic_surface_exactly():
    # a global cubic lies in the span of the C0 fit: the fit and height_at are exact
    y, x = np.mgrid[0:33, 0:41] * 1.5
    f = lambda x, y: 0.001 * x**3 - 0.002 * x * y**2 + 0.05 * x * y + 0.3 * y + 2.0  # noqa: E731
    net = fit_heightfield(f(x, y), 1.5)
    rng = np.random.default_rng(0)
    q = rng.uniform([0, 0], [60, 48], (5000, 2))
    z, hit, patch, uv = height_at(net, q)
    assert hit.all()
    np.testing.assert_allclose(z, f(q[:, 0], q[:, 1]), atol=1e-8)
    # the reported patch and (u, v) evaluate back to the query point
    p = eval_points(net.control_points[patch], uv[:, 0], uv[:, 1], derivatives=False)
    np.testing.assert_allclose(p[:, :2], q, atol=1e-9)
    assert ((uv >= 0) & (uv <= 1)).all()


def test_height_at_misses_and_single_point():
    net = flat_net(2, 2.0, z=3.0)
    z, hit, patch, uv = height_at(net, np.array([[1.0, 1.0], [-0.1, 1.0], [4.0, 4.0], [4.01, 2.0], [np.nan, 1.0]]))
    assert hit.tolist() == [True, False, True, False, False]
    assert np.isnan(z[~hit]).all() and (patch[~hit] == -1).all() and np.isnan(uv[~hit]).all()
    np.testing.assert_allclose(z[hit], 3.0)
    z1, hit1, p1, uv1 = height_at(net, (3.0, 1.0))
    assert hit1 and z1 == pytest.approx(3.0) and p1 == 1
    with pytest.raises(ValidationError):
        height_at(net, np.zeros((3, 3)))


def test_height_at_warped_patch_newton():
    # x and y are not linear in (u, v): Newton must invert the warp
    rng = np.random.default_rng(3)
    t = np.arange(4) / 3.0
    cp = np.empty((1, 4, 4, 3))
    cp[0, :, :, 0] = 10 * t[:, None] + 1.5 * np.sin(3 * t[None, :])
    cp[0, :, :, 1] = 10 * t[None, :] + 1.0 * t[:, None] ** 2
    cp[0, :, :, 2] = rng.normal(size=(4, 4))
    net = PatchNet(cp)
    uv = rng.uniform(0.05, 0.95, (500, 2))
    pts = eval_points(np.repeat(cp, 500, 0), uv[:, 0], uv[:, 1], derivatives=False)
    z, hit, patch, uv2 = height_at(net, pts[:, :2])
    assert hit.all()
    np.testing.assert_allclose(uv2, uv, atol=1e-9)
    np.testing.assert_allclose(z, pts[:, 2], atol=1e-9)


@pytest.mark.parametrize("use_numba", [False, True])
def test_height_at_compiled_equals_numpy(use_numba):
    """The compiled Newton (the default once numba has loaded) against the numpy iteration, on a
    fitted course with misses outside it, a warped patch and the teapot (patches over one another):
    the same hits and patches, z and (u, v) to 1e-9."""
    from piste.world.course import default_course

    rng = np.random.default_rng(11)
    t = np.arange(4) / 3.0
    cp = np.empty((1, 4, 4, 3))
    cp[0, :, :, 0] = 10 * t[:, None] + 1.5 * np.sin(3 * t[None, :])
    cp[0, :, :, 1] = 10 * t[None, :] + 1.0 * t[:, None] ** 2
    cp[0, :, :, 2] = rng.normal(size=(4, 4))
    for net in (default_course(0), PatchNet(cp), PatchNet.from_bpt(TEAPOT)):
        lo, hi = net.bounds
        xy = rng.uniform(lo[:2] - 5.0, hi[:2] + 5.0, (3000, 2))
        ref = height_at(net, xy, use_numba=False)
        got = height_at(net, xy, use_numba=use_numba)
        assert np.array_equal(ref[1], got[1]) and np.array_equal(ref[2], got[2])
        np.testing.assert_allclose(got[0], ref[0], atol=1e-9, equal_nan=True)
        np.testing.assert_allclose(got[3], ref[3], atol=1e-9, equal_nan=True)
        assert ref[1].any()


# --------------------------------------------------------------------------- ray_intersect
def test_rays_flat_patch_analytic():
    net = flat_net(3, 2.0, z=1.0)
    rng = np.random.default_rng(0)
    target = np.c_[rng.uniform(0, 6, (400, 2)), np.ones(400)]
    o = target + rng.normal(size=(400, 3)) * [3, 3, 0] + [0, 0, 5]
    d = target - o
    d *= rng.uniform(0.2, 3.0, (400, 1))  # not unit: t is in units of |d|
    r = ray_intersect(net, o, d)
    assert r.hit.all()
    np.testing.assert_allclose(r.position, target, atol=1e-9)
    np.testing.assert_allclose(o + r.t[:, None] * d, target, atol=1e-9)
    np.testing.assert_allclose(r.normal, np.tile([0, 0, 1.0], (400, 1)), atol=1e-12)
    back = ray_intersect(net, o, -d)  # pointing away
    assert not back.hit.any() and np.isinf(back.t).all() and (back.patch == -1).all()
    assert np.isnan(back.position).all()


def test_rays_parallel_to_flat_surface_miss():
    net = flat_net(3, 2.0, z=1.0)
    o = np.array([[-1.0, 1.0, 1.5], [-1.0, 1.0, 0.5], [-1.0, 3.0, 1.0], [3.0, 3.0, 1.0]])
    d = np.array([[1.0, 0.1, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    r = ray_intersect(net, o, d)
    # above, below, and lying in the plane (no isolated intersection): all reported as misses
    assert not r.hit.any()


def test_rays_paraboloid_analytic():
    a = 0.5
    net = paraboloid_net(a)
    rng = np.random.default_rng(1)
    k = 3000
    o = np.c_[rng.uniform(-1.5, 1.5, (k, 2)), rng.uniform(1.2, 4.0, k)]
    tgt = np.c_[rng.uniform(-1.1, 1.1, (k, 2)), rng.uniform(-0.2, 1.0, k)]
    d = (tgt - o) * rng.uniform(0.5, 2.0, (k, 1))
    r = ray_intersect(net, o, d)
    # analytic: a((ox + t dx)^2 + (oy + t dy)^2) = oz + t dz
    qa = a * (d[:, 0] ** 2 + d[:, 1] ** 2)
    qb = 2 * a * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]) - d[:, 2]
    qc = a * (o[:, 0] ** 2 + o[:, 1] ** 2) - o[:, 2]
    disc = qb**2 - 4 * qa * qc
    t_exact = np.full(k, np.inf)
    sq = np.sqrt(np.maximum(disc, 0))
    for root in ((-qb - sq) / (2 * qa), (-qb + sq) / (2 * qa)):
        p = o + root[:, None] * d
        ok = (disc >= 0) & (root > 0) & (np.abs(p[:, :2]) <= 1).all(1)
        t_exact = np.where(ok & (root < t_exact), root, t_exact)
    expect = np.isfinite(t_exact)
    # rays within 1e-6 of the patch rim may go either way
    p_exact = o + np.where(expect, t_exact, 0)[:, None] * d
    rim = expect & (np.abs(np.abs(p_exact[:, :2]) - 1).min(1) < 1e-6)
    assert expect.sum() > 1000
    assert (r.hit == expect)[~rim].all()
    both = r.hit & expect
    size = 2 * np.sqrt(2)
    err = np.abs(r.t[both] - t_exact[both]) * np.linalg.norm(d[both], axis=1)
    assert err.max() < 1e-5 * size
    # position on the analytic surface, normal is the analytic one
    pos = r.position[both]
    np.testing.assert_allclose(pos[:, 2], a * (pos[:, 0] ** 2 + pos[:, 1] ** 2), atol=1e-5 * size)
    n = np.c_[-2 * a * pos[:, 0], -2 * a * pos[:, 1], np.ones(len(pos))]
    n /= np.linalg.norm(n, axis=1)[:, None]
    np.testing.assert_allclose(r.normal[both], n, atol=1e-6)


def test_rays_from_below_hit_the_inside_of_a_bowl_twice():
    # rays from inside the bowl going up and out: origin below the rim; rays through the bottom from
    # beneath: the nearest of the two roots must be reported
    net = paraboloid_net(0.5)
    o = np.array([[-3.0, 0.0, 0.2], [0.0, -3.0, 0.1]])
    d = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    r = ray_intersect(net, o, d)
    assert r.hit.all()
    # z = 0.5 x^2 = 0.2  ->  x = -sqrt(0.4)
    np.testing.assert_allclose(r.position[0], [-np.sqrt(0.4), 0, 0.2], atol=1e-9)
    np.testing.assert_allclose(r.position[1], [0, -np.sqrt(0.2), 0.1], atol=1e-9)


def test_rays_starting_on_the_surface():
    net = paraboloid_net(0.5)
    rng = np.random.default_rng(2)
    uv = rng.uniform(0.1, 0.9, (300, 2))
    o = eval_points(np.repeat(net.control_points, 300, 0), uv[:, 0], uv[:, 1], derivatives=False)
    d = rng.normal(size=(300, 3))
    d[:, :2] *= 0.4
    d[:, 2] = np.abs(d[:, 2]) + 2.0  # steeper than the bowl anywhere: never meets it again
    # t_min skips the origin's own root (the shadow-ray epsilon)
    r = ray_intersect(net, o, d, t_min=1e-6)
    assert not r.hit.any()
    r0 = ray_intersect(net, o, d, t_min=-1e-6)  # the origin itself is a hit, at t ~ 0 (either sign)
    assert r0.hit.mean() > 0.9 and np.abs(r0.t[r0.hit]).max() < 1e-9
    # a ray from a bowl's floor towards its far wall hits the wall (a second root in the same patch)
    o2 = np.array([[-0.2, 0.0, 0.02]])
    r2 = ray_intersect(net, o2, np.array([[1.0, 0.0, 0.2]]), t_min=1e-6)
    assert r2.hit[0]  # 0.02 + 0.2 (x + 0.2) = 0.5 x^2  ->  x = 0.6
    np.testing.assert_allclose(r2.position[0], [0.6, 0.0, 0.18], atol=1e-9)
    assert r2.t[0] == pytest.approx(0.8, abs=1e-9)


def test_rays_against_dense_sampling_and_any_hit():
    net = bumpy_net()
    rng = np.random.default_rng(4)
    k = 300
    (x0, y0, _), (x1, y1, z1) = net.bounds
    o = np.c_[rng.uniform(x0 - 10, x1 + 10, (k, 2)), rng.uniform(z1 - 2, z1 + 20, k)]
    tgt = np.c_[rng.uniform(x0, x1, (k, 2)), rng.uniform(-5, 5, k)]
    d = tgt - o
    d /= np.linalg.norm(d, axis=1)[:, None]
    r = ray_intersect(net, o, d)
    t_mesh = brute_rays(dense_mesh(net), o, d)
    agree = r.hit == np.isfinite(t_mesh)
    assert agree.mean() > 0.98 and r.hit.sum() > 100
    both = r.hit & np.isfinite(t_mesh)
    # the mesh's own error (10 m patches at 32 intervals), larger for grazing rays
    steep = np.abs(np.einsum("kc,kc->k", r.normal, d))
    assert (np.abs(r.t[both] - t_mesh[both]) * np.maximum(steep[both], 0.05)).max() < 0.03
    # exactness: the reported point is on the exact surface and on the ray
    size = np.median(net.patch_size)
    q = eval_points(net.control_points[r.patch[r.hit]], r.u[r.hit], r.v[r.hit], derivatives=False)
    assert np.abs(q - (o + r.t[:, None] * d)[r.hit]).max() < 1e-5 * size
    # any_hit finds a hit for exactly the same rays
    ra = ray_intersect(net, o, d, any_hit=True)
    assert (ra.hit == r.hit).all() and (ra.t[ra.hit] >= r.t[ra.hit] - 1e-9).all()
    # t_max cuts rays short
    rt = ray_intersect(net, o, d, t_max=np.where(r.hit, r.t - 1e-3, np.inf))
    assert not rt.hit[r.hit].any()
    # split-1 and split-4 hierarchies agree
    for split in (1, 4):
        rs = ray_intersect(net, o, d, bvh=PatchBVH(net, split))
        assert (rs.hit == r.hit).all()
        np.testing.assert_allclose(rs.t[r.hit], r.t[r.hit], atol=1e-7)


def test_rays_down_match_height_at():
    net = bumpy_net(5)
    rng = np.random.default_rng(5)
    (x0, y0, _), (x1, y1, z1) = net.bounds
    xy = rng.uniform([x0, y0], [x1, y1], (2000, 2))
    z, hit, _, _ = height_at(net, xy)
    r = ray_intersect(net, np.c_[xy, np.full(2000, z1 + 5)], np.tile([0, 0, -1.0], (2000, 1)))
    assert hit.all() and r.hit.all()
    np.testing.assert_allclose(r.position[:, 2], z, atol=1e-8)


def test_rays_teapot_with_degenerate_patches():
    net = PatchNet.from_bpt(TEAPOT)
    rng = np.random.default_rng(6)
    k = 200
    dirs = rng.normal(size=(k, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    centre = np.array([0.0, 0.0, 1.5])
    o = centre + 8.0 * dirs
    tgt = centre + rng.normal(size=(k, 3)) * 0.3
    d = tgt - o
    d /= np.linalg.norm(d, axis=1)[:, None]
    r = ray_intersect(net, o, d)
    t_mesh = brute_rays(dense_mesh(net, 25), o, d)
    assert r.hit.mean() > 0.9
    agree = r.hit == np.isfinite(t_mesh)
    assert agree.mean() > 0.97
    both = r.hit & np.isfinite(t_mesh)
    assert np.abs(r.t[both] - t_mesh[both]).max() < 0.02
    np.testing.assert_allclose(np.linalg.norm(r.normal[r.hit], axis=1), 1.0, atol=1e-9)


def test_bvh_cache_and_errors():
    net = flat_net(2, 2.0, z=1.0)
    o, d = np.array([[1.0, 1.0, 5.0]]), np.array([[0.0, 0.0, -1.0]])
    assert ray_intersect(net, o, d).t[0] == pytest.approx(4.0)
    net.control_points = net.control_points + [0.0, 0.0, 1.0]  # a new array: caches rebuild
    assert ray_intersect(net, o, d).t[0] == pytest.approx(3.0)
    assert height_at(net, [1.0, 1.0])[0] == pytest.approx(2.0)
    net.control_points[..., 2] += 1.0  # in place: needs clear_cache
    clear_cache(net)
    assert ray_intersect(net, o, d).t[0] == pytest.approx(2.0)
    with pytest.raises(ValidationError, match="zero"):
        ray_intersect(net, o, np.zeros((1, 3)))
    with pytest.raises(ValidationError, match="shape"):
        ray_intersect(net, o, np.zeros((2, 3)))
    with pytest.raises(ValidationError, match="finite"):
        ray_intersect(net, np.array([[np.nan, 0, 0]]), d)
