"""Object levels of detail: the chain over one vertex set, and the per-instance choice in pixels."""

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.world.object_lod import choose_lods, instance_scale, object_lods
from piste.world.objects import compress_mesh, make_mesh


def _chain(kind):
    m = compress_mesh(make_mesh(kind))
    return m, object_lods(m.decode()[0], m.indices)


@pytest.mark.parametrize("kind", ["tree", "rock"])
def test_chain_coarsens_over_the_same_vertices(kind):
    m, lods = _chain(kind)
    assert len(lods) >= 3
    assert np.array_equal(lods[0].indices, m.indices.astype(np.uint32)) and lods[0].error == 0.0
    tris = [lv.n_triangles for lv in lods]
    errs = [lv.error for lv in lods]
    assert all(b < a for a, b in zip(tris, tris[1:]))
    assert all(b > a for a, b in zip(errs, errs[1:]))
    for lv in lods:
        assert lv.indices.shape[1] == 3 and lv.indices.max() < m.n_vertices
        # no degenerate triangles
        t = lv.indices
        assert np.all((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2]))
    # the error is real: every kept vertex of a coarse level is an original vertex, and the coarse
    # surface stays within a few errors of the original's bounding box
    p = m.decode()[0]
    lo, hi = p.min(0), p.max(0)
    used = p[np.unique(lods[-1].indices)]
    assert np.all(used >= lo - 1e-6) and np.all(used <= hi + 1e-6)


def test_boxes_keep_their_full_mesh():
    # a box is as coarse as it gets: the chain stops at the full mesh (rail: three boxes)
    _, lods = _chain("rail")
    assert len(lods) == 1


def test_bad_ratio():
    with pytest.raises(ConfigError):
        object_lods(np.zeros((3, 3)), np.array([[0, 1, 2]]), ratio=1.5)


def _vp(fov_y=60.0, aspect=640 / 448):
    from piste.world.camera import Camera

    return Camera(eye=(0, -10, 0), target=(0, 0, 0), fov_y=fov_y, aspect=aspect, near=0.5, far=5000).view_projection()


def test_choose_lods_by_projected_error():
    errors = np.array([0.0, 0.01, 0.1, 1.0])
    vp = _vp()
    # along the view axis: the camera at y=-10 looks along +y
    d = np.array([1.0, 30.0, 300.0, 3000.0, 30000.0])
    centers = np.stack([np.zeros_like(d), -10 + d, np.zeros_like(d)], 1)
    lv = choose_lods(errors, centers, np.zeros(5), np.ones(5), vp, 448, 0.5)
    assert lv.tolist() == sorted(lv.tolist()) and lv[0] == 0 and lv[-1] == 3
    # the rule itself: pixels = error * f * H/2 / depth
    f = 1.0 / np.tan(np.radians(30.0))
    px = errors[None, :] * f * 224 / d[:, None]
    want = (px <= 0.5).sum(1) - 1
    assert lv.tolist() == want.tolist()
    # 0 px: always the full mesh; a bigger instance (scale 10) needs a finer level; the radius counts
    assert choose_lods(errors, centers, np.zeros(5), np.ones(5), vp, 448, 0.0).tolist() == [0] * 5
    big = choose_lods(errors, centers, np.zeros(5), np.full(5, 10.0), vp, 448, 0.5)
    assert np.all(big <= lv) and np.any(big < lv)
    near = choose_lods(errors, centers, np.full(5, 50.0), np.ones(5), vp, 448, 0.5)
    assert np.all(near <= lv) and np.any(near < lv)
    # per-instance error rows with inf padding (a kind with two levels never takes level 2 or 3)
    rows = np.tile(errors, (5, 1))
    rows[:, 2:] = np.inf
    assert choose_lods(rows, centers, np.zeros(5), np.ones(5), vp, 448, 0.5).max() == 1
    # wholly behind the eye: the coarsest level it has (the clamped depth used to give the full mesh);
    # a sphere reaching in front of the eye still counts as near
    back = np.array([[0.0, -12.0, 0.0], [0.0, -10.5, 0.0], [0.0, -12.0, 0.0]])
    got = choose_lods(np.vstack([errors, errors, rows[0]]), back, np.array([1.0, 1.0, 1.0]), np.ones(3), vp, 448, 0.5)
    assert got.tolist() == [3, 0, 1]


def test_instance_scale():
    m = np.tile(np.eye(4), (2, 1, 1))
    m[1, :3, :3] = np.diag([2.0, 3.0, 0.5])
    assert np.allclose(instance_scale(m), [1.0, 3.0])


def test_choose_lods_orthographic():
    from piste.world.camera import Camera

    errors = np.array([0.0, 0.01, 0.1, 1.0])
    # 20 m tall orthographic view on 448 pixels: 22.4 px a metre at any depth
    vp = Camera(eye=(0, -10, 0), target=(0, 0, 0), ortho_height=20.0, aspect=1.0, near=0.5, far=5000).view_projection()
    centers = np.array([[0.0, 5.0, 0.0], [0.0, 500.0, 0.0]])
    lv = choose_lods(errors, centers, np.full(2, 3.0), np.ones(2), vp, 448, 0.5)
    px = errors * 448 / 20.0
    want = int((px <= 0.5).sum() - 1)
    assert lv.tolist() == [want, want] and want == 1


def test_chain_goes_down_to_a_few_triangles():
    # six levels by default: a rock (320 triangles) halves down to 10, every level with a larger error
    _, lods = _chain("rock")
    assert len(lods) == 6 and lods[-1].n_triangles <= 16
    m, _ = _chain("rock")
    four = object_lods(m.decode()[0], m.indices, max_levels=4)  # (the previous default)
    assert [lv.n_triangles for lv in four] == [lv.n_triangles for lv in lods[:4]] and four[-1].n_triangles > 16


def test_prune_goes_past_a_stalled_chain():
    # the tree's connected simplification stalls (trunk and crown apart); pruning small parts goes on,
    # its error still ascending; off by default (a rail would lose whole boxes)
    m, plain = _chain("tree")
    pruned = object_lods(m.decode()[0], m.indices, prune=True)
    assert pruned[-1].n_triangles < plain[-1].n_triangles
    errs = [lv.error for lv in pruned]
    assert all(b > a for a, b in zip(errs, errs[1:]))
    rail, _ = _chain("rail")
    assert len(object_lods(rail.decode()[0], rail.indices, prune=True)) > 1


@pytest.mark.parametrize("kind", ["tree", "rock", "rail"])
def test_stored_chain_round_trips(kind):
    from piste.world.object_lod import lod_arrays, stored_lods

    m, lods = _chain(kind)
    a = lod_arrays(lods)
    assert a["lod_indices"].dtype == np.uint32 and a["lod_errors"].dtype == np.float64
    back = stored_lods(a["lod_indices"], a["lod_triangles"], a["lod_errors"], m.n_vertices, m.n_triangles)
    assert len(back) == len(lods)
    for got, ref in zip(back, lods):
        assert np.array_equal(got.indices, ref.indices) and got.error == ref.error


def test_stored_chain_that_does_not_fit_its_mesh_is_refused():
    from piste.errors import ValidationError
    from piste.world.object_lod import lod_arrays, stored_lods

    m, lods = _chain("tree")
    a = lod_arrays(lods)
    args = (a["lod_indices"], a["lod_triangles"], a["lod_errors"])
    with pytest.raises(ValidationError, match="lod_triangles: expected"):
        stored_lods(*args, m.n_vertices, m.n_triangles + 1)  # another mesh's chain
    with pytest.raises(ValidationError, match="past the mesh"):
        stored_lods(*args, 3, m.n_triangles)
    with pytest.raises(ValidationError, match="lod_indices: expected"):
        stored_lods(a["lod_indices"][:-3], *args[1:], m.n_vertices, m.n_triangles)
    with pytest.raises(ValidationError, match="lod_errors: expected 0 then"):
        stored_lods(args[0], args[1], args[2][::-1].copy(), m.n_vertices, m.n_triangles)
    with pytest.raises(ValidationError, match="lod_indices: expected a flat uint32"):
        stored_lods(args[0].astype(np.int64), args[1], args[2], m.n_vertices, m.n_triangles)
