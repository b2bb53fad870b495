"""Occlusion culling (issue 27 item 6): the conservative software hierarchical-Z of the near terrain
(piste.render.occlusion) and the frames it culls, pixel for pixel the frames without it."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.render.occlusion import HiZ, occluder_depth
from piste.world.camera import Camera

SIZE = (64, 48)


def _camera():
    return Camera(np.array([0.0, -10.0, 0.0]), np.array([0.0, 0.0, 0.0]), up=np.array([0.0, 0.0, 1.0]),
                  fov_y=60.0, near=0.5, far=100.0).with_aspect(*SIZE)


def _wall(y=0.0, half=3.0, n=4):
    """A square wall at ``y`` facing the camera (-y), ``n x n`` quads: ``(v, 3), (t, 3)``."""
    g = np.linspace(-half, half, n + 1)
    x, z = np.meshgrid(g, g, indexing="xy")
    pos = np.stack([x.ravel(), np.full(x.size, y), z.ravel()], -1)
    k = np.arange(n * n)
    a = (k // n) * (n + 1) + k % n
    tris = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    return pos, tris


def _hiz(pos, tris, cell=4):
    vp = _camera().view_projection()
    return HiZ(occluder_depth(pos, tris, vp, SIZE, cell), vp, SIZE, cell)


def test_wall_covers_cells_with_its_depth_bound():
    pos, tris = _wall()
    vp = _camera().view_projection()
    d = occluder_depth(pos, tris, vp, SIZE, 4)
    assert d.shape == (12, 16)
    inner = np.isfinite(d)
    assert inner.sum() > 10 and not inner.all()  # the wall's middle, not the sky round it
    # the wall's own depth (a plane facing the camera: one depth) bounds every covered cell from above
    clip = np.c_[pos, np.ones(len(pos))] @ vp.T
    z = clip[:, 2] / clip[:, 3]
    assert np.all(d[inner] >= z.min() - 1e-9) and np.all(d[inner] <= z.max() + 1e-9)


def test_back_faces_and_split_triangles_cover_nothing():
    pos, tris = _wall()
    assert np.isinf(occluder_depth(pos, tris[:, ::-1], _camera().view_projection(), SIZE, 4)).all()
    # the same wall as separate patches (each with its own copy of the shared vertices) still covers
    half = len(tris) // 2
    pos2 = np.concatenate([pos, pos])
    tris2 = np.concatenate([tris[:half], tris[half:] + len(pos)])
    a = occluder_depth(pos, tris, _camera().view_projection(), SIZE, 4)
    b = occluder_depth(pos2, tris2, _camera().view_projection(), SIZE, 4)
    assert np.array_equal(np.isfinite(a), np.isfinite(b))


def test_boxes_behind_hidden_in_front_or_beside_kept():
    pos, tris = _wall()
    hz = _hiz(pos, tris)
    lo = np.array([[-0.3, 3.0, -0.3], [-0.3, -3.0, -0.3], [5.0, 3.0, -0.3], [-0.3, 3.0, -0.3], [-0.3, -11.0, -0.3]])
    hi = np.array([[0.3, 4.0, 0.3], [0.3, -2.0, 0.3], [6.0, 4.0, 0.3], [0.3, 3.2, 3.0], [0.3, -9.0, 0.3]])
    # behind the wall's middle; in front of it; behind but beside it; behind, reaching past its top;
    # round the eye
    assert hz.occluded(lo, hi).tolist() == [True, False, False, False, False]
    assert hz.occluded(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


def test_a_wall_with_a_hole_does_not_hide_what_shows_through():
    pos, tris = _wall(n=8)
    keep = np.ones(len(tris), bool)
    keep[[27, 27 + 64]] = False  # one quad out of the middle
    hz = _hiz(pos, tris[keep], cell=2)
    c = pos[tris[27]].mean(0)
    box = (c + [-0.05, 3.0, -0.05], c + [0.05, 3.1, 0.05])
    assert not hz.occluded(np.array([box[0]]), np.array([box[1]]))[0]
    assert hz.occluded(np.array([[2.0, 3.0, 2.0]]), np.array([[2.1, 3.1, 2.1]]))[0]  # (away from the hole)


def test_bad_cell_is_a_clear_error():
    pos, tris = _wall()
    with pytest.raises(RenderError, match="cell"):
        occluder_depth(pos, tris, _camera().view_projection(), SIZE, 0)


@pytest.fixture(scope="module")
def default_bundle(_piste_cache_dir):
    import os

    old = os.environ.get("PISTE_CACHE_DIR")
    os.environ["PISTE_CACHE_DIR"] = str(_piste_cache_dir)
    try:
        from piste.pipeline.bundle_objects import load_bundle
        from piste.pipeline.default_scene import build_default_scene

        return load_bundle(build_default_scene(0).path, verify=False)
    finally:
        if old is None:
            os.environ.pop("PISTE_CACHE_DIR", None)
        else:
            os.environ["PISTE_CACHE_DIR"] = old


def test_default_course_culls_and_no_pixel_changes(gl_context, default_bundle):
    """The demo's chase camera at t = 0 and the course's flight camera near its end: patches and objects
    behind the course's ridges culled, and the frames the same to the last pixel."""
    from piste.pipeline.preview import ScenePreview, camera_at

    pv = {o: ScenePreview(default_bundle, size=(320, 224), ctx=gl_context, occlusion=o) for o in (False, True)}
    try:
        culled = {"patches": 0, "objects": 0}
        for cam in (None, camera_at(default_bundle, "flight", 4, 5)):
            a = pv[False].render(cam, 0.0)
            b = pv[True].render(cam, 0.0)
            off, on = pv[False].frame.stats, pv[True].frame.stats
            assert "occluded_patches" not in off
            assert on["terrain_patches"] == off["terrain_patches"] - on["occluded_patches"]
            assert on["objects_drawn"] == off["objects_drawn"] - on["occluded_objects"]
            culled["patches"] += on["occluded_patches"]
            culled["objects"] += on["occluded_objects"]
            assert int(np.any(a != b, axis=-1).sum()) == 0
        assert culled["patches"] > 50 and culled["objects"] > 5, culled
    finally:
        for p in pv.values():
            p.release()


def test_flags_and_scene_keys_reach_the_runtime(tmp_path, monkeypatch, default_bundle):
    """``--occlusion on|off`` / ``--soft-shadows`` and ``[render] occlusion`` / ``soft_shadows``: parsed
    by the commands, handed to the runtime as parameters (off by default)."""
    from piste.cli import build_parser, main
    from piste.errors import PisteError
    from piste.world.scene_file import loads_scene

    assert build_parser().parse_args(["render", "x.toml", "--occlusion", "on"]).occlusion == "on"
    assert build_parser().parse_args(["demo"]).occlusion is None
    assert build_parser().parse_args(["view", "x.toml", "--soft-shadows"]).soft_shadows is True
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["render", "x.toml", "--occlusion", "maybe"])
    assert exc.value.code == 2
    spec = loads_scene("[render]\nocclusion = true\nsoft_shadows = true\n", tmp_path / "o.toml").render
    assert spec.occlusion is True and spec.soft_shadows is True
    plain = loads_scene("", tmp_path / "p.toml").render
    assert plain.occlusion is False and plain.soft_shadows is False
    with pytest.raises(PisteError, match="occlusion") as bad:
        loads_scene("[render]\nocclusion = \"yes\"\n", tmp_path / "bad.toml")
    assert "bad.toml" in str(bad.value)

    import piste.pipeline.preview as preview

    seen = {}
    monkeypatch.setattr(preview, "render_frames", lambda *a, **kw: seen.update(kw) or [{}])
    assert main(["render", str(default_bundle.path), "--occlusion", "on", "--soft-shadows",
                 "--out", str(tmp_path / "a.png")]) == 0
    assert seen["occlusion"] is True and seen["soft_shadows"] is True
    assert main(["render", str(default_bundle.path), "--out", str(tmp_path / "b.png")]) == 0
    assert seen["occlusion"] is None and seen["soft_shadows"] is None


def test_scene_file_key_turns_it_on(gl_context, default_bundle):
    from piste.pipeline.preview import ScenePreview

    default_bundle.manifest.setdefault("render", {})
    saved = dict(default_bundle.manifest["render"])
    default_bundle.manifest["render"].update(occlusion=True, soft_shadows=True)
    try:
        p = ScenePreview(default_bundle, size=(64, 48), ctx=gl_context)
        q = ScenePreview(default_bundle, size=(64, 48), ctx=gl_context, occlusion=False, soft_shadows=False)
        try:
            assert p.renderer.occlusion is True and p.renderer.shadows.soft is True
            assert q.renderer.occlusion is False and q.renderer.shadows.soft is False
        finally:
            p.release()
            q.release()
    finally:
        default_bundle.manifest["render"] = saved
