"""Instance groups in the object pass (issue 26: a tiled world's objects paged with their tiles):
groups added and removed by key draw exactly what one set of the same instances draws, the
instance buffers grow, baked colours follow their group, and a scene holding the set sees the
same instances as the pass."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.lighting import AmbientLight, DirectionalLight, Lights
from piste.lighting.vertex import choose_lights_many

LIGHTS = Lights((AmbientLight((0.35, 0.4, 0.5), 0.5),
                 DirectionalLight((-0.35, 0.75, -0.55), (1.0, 0.9, 0.75), 0.8, name="key")))


def _instances(n=24, seed=0):
    rng = np.random.default_rng(seed)
    kind = rng.integers(0, 4, n)
    mats = np.tile(np.eye(4), (n, 1, 1))
    mats[:, 0, 3] = rng.uniform(-30, 30, n)
    mats[:, 1, 3] = rng.uniform(20, 120, n)
    mats[:, :3, :3] *= rng.uniform(0.7, 1.4, n)[:, None, None]
    return kind, mats


def _plain(kind, mats):
    from piste.pipeline.tile_objects import object_set

    return object_set(kind, mats, LIGHTS)


def _empty():
    from piste.render.object_pass import ObjectGroups

    s = _plain(np.zeros(0, np.int64), np.zeros((0, 4, 4)))
    return ObjectGroups(s.meshes, s.kinds, s.texture, s.blend, world_lights=LIGHTS)


def _draw(gl, op, target):
    from piste.world.camera import Camera

    cam = Camera(eye=(0.0, -5.0, 12.0), target=(0.0, 70.0, 2.0), fov_y=60, aspect=320 / 224, near=0.5, far=1000)
    target.use()
    target.fbo.clear(0.8, 0.86, 0.93, 1.0)
    vis = op.objects.visible(cam.frustum_planes(), max_distance=cam.far, eye=cam.eye)
    op.draw(cam.view_projection(), cam.eye, vis)
    return target.read()[..., :3].copy(), op.drawn


@pytest.fixture
def target(gl):
    from piste.render.context import Offscreen

    t = Offscreen(gl, (320, 224))
    yield t
    t.release()


@pytest.mark.parametrize("mode", ["dynamic", "baked"])
def test_groups_draw_what_one_set_draws(gl, target, mode):
    from piste.render.object_pass import ObjectPass

    kind, mats = _instances(30)
    ref_pass = ObjectPass(gl, _plain(kind, mats), LIGHTS, mode=mode)
    ref, n_ref = _draw(gl, ref_pass, target)
    ref_pass.release()
    groups = _empty()
    op = ObjectPass(gl, groups, LIGHTS, mode=mode)
    try:
        blank, n0 = _draw(gl, op, target)
        assert n0 == 0
        for key, sl in (("a", slice(0, 4)), ("b", slice(4, 17)), ("c", slice(17, 30))):  # the buffers grow
            op.add_group(key, kind[sl], mats[sl])
        img, n = _draw(gl, op, target)
        assert n == n_ref == 30 and op.group_keys == ["a", "b", "c"]
        assert np.array_equal(img, ref), f"{int((img != ref).any(2).sum())} pixels differ"
        assert op.objects is groups and len(groups) == 30  # the set itself changed (a scene culling it agrees)
        # one group leaves: the picture of the other two alone
        assert op.remove_group("b") and not op.remove_group("b")
        keep = np.r_[0:4, 17:30]
        other = ObjectPass(gl, _plain(kind[keep], mats[keep]), LIGHTS, mode=mode)
        want, _ = _draw(gl, other, target)
        other.release()
        img2, n2 = _draw(gl, op, target)
        assert n2 == 17 and np.array_equal(img2, want)
        assert not np.array_equal(img2, img)
        op.remove_group("a")
        op.remove_group("c")
        img3, n3 = _draw(gl, op, target)
        assert n3 == 0 and np.array_equal(img3, blank)
    finally:
        op.release()


def test_a_plain_set_takes_groups_and_baked_colours_follow(gl, target):
    from piste.render.object_pass import ObjectPass
    from piste.world.objects import bake_vertex_colors

    kind, mats = _instances(20, seed=3)
    first = _plain(kind[:8], mats[:8])
    op = ObjectPass(gl, first, LIGHTS, mode="baked", colors=bake_vertex_colors(first, LIGHTS))
    try:
        _draw(gl, op, target)
        later = _plain(kind[8:], mats[8:])
        dark = {k: np.zeros_like(c) for k, c in bake_vertex_colors(later, LIGHTS).items()}
        op.add_group("dark", kind[8:], mats[8:], colors=dark)  # given colours are drawn, not re-baked
        img, n = _draw(gl, op, target)
        assert n == 20 and op.group_keys == [None, "dark"]
        lit = ObjectPass(gl, _plain(kind, mats), LIGHTS, mode="baked")
        ref, _ = _draw(gl, lit, target)
        lit.release()
        assert (img.astype(int).sum(2) < ref.astype(int).sum(2)).sum() > 50  # the dark group is darker
        with pytest.raises(RenderError, match="baked colours of 'tree'"):
            op.add_group("bad", kind[:2], mats[:2], colors={"tree": np.zeros((5, 3, 3), np.uint8)})
        with pytest.raises(RenderError, match="kinds must index"):
            op.add_group("bad", np.array([7]), mats[:1])
    finally:
        op.release()


def test_group_vertex_lights_are_chosen_per_instance(gl):
    kind, mats = _instances(6)
    g = _empty()
    part = g.add("x", kind, mats)
    ref = _plain(kind, mats)
    assert np.allclose(part.center, ref.center) and np.allclose(part.radius, ref.radius)
    want = choose_lights_many(LIGHTS, ref.center)
    assert np.allclose(g.lights.directions, want.directions) and np.allclose(g.lights.ambient, want.ambient)
    v = g.version
    g.remove("x")
    assert g.version == v + 1 and len(g) == 0 and g.lights is None


def test_a_group_change_rebuilds_only_instance_data(gl, target, monkeypatch):
    """Adding or removing a group computes only that group's rows: the meshes' buffers, LOD chains,
    programs and the atlas stay; rows of groups already there are not computed again."""
    import piste.render.object_pass as OP

    kind, mats = _instances(40, seed=5)
    op = OP.ObjectPass(gl, _empty(), LIGHTS, mode="dynamic")
    try:
        op.add_group("a", kind[:20], mats[:20])
        _draw(gl, op, target)  # (programs and vertex arrays made)
        keep = ([id(b) for info in op.kinds for b in info["buffers"]], id(op.texture), [id(info["lods"]) for info in op.kinds],
                {k: id(p) for k, (p, _) in op._programs.items()})
        rows_of = []
        real = OP.instance_rows
        monkeypatch.setattr(OP, "instance_rows", lambda objs: rows_of.append(len(objs)) or real(objs))
        op.add_group("b", kind[20:], mats[20:])
        op.remove_group("a")
        _draw(gl, op, target)
        assert rows_of == [20]  # the new group's rows alone
        assert keep == ([id(b) for info in op.kinds for b in info["buffers"]], id(op.texture),
                        [id(info["lods"]) for info in op.kinds], {k: id(p) for k, (p, _) in op._programs.items()})
        assert len(op.rows) == 20 and np.array_equal(op.rows[:, 0:4, :], np.swapaxes(mats[20:], 1, 2).astype(np.float32))
    finally:
        op.release()


def test_change_adds_and_removes_many_groups_at_once():
    """``change`` is the same set as adds and removes one by one, concatenated once."""
    a, b = _empty(), _empty()
    groups = {k: _instances(6 + k, seed=k) for k in range(5)}
    for k in (0, 1, 2):
        a.add(k, *groups[k])
        b.add(k, *groups[k])
    v = b.version
    assert b.change({3: groups[3], 4: groups[4], 0: groups[0]}, remove=[1, 7]) == 4  # 7: not there
    assert b.version == v + 1
    a.remove(1)
    a.remove(0)
    a.add(3, *groups[3])
    a.add(4, *groups[4])
    a.add(0, *groups[0])
    assert list(a.groups) == list(b.groups) == [2, 3, 4, 0] and b.colors[0] is None
    for name in ("kind", "matrix", "normal_matrix", "center", "radius"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert np.array_equal(a.lights.directions, b.lights.directions) and a.counts == b.counts
    assert b.change({}, remove=[9]) == 0 and b.version == v + 1  # nothing changed: no new version
