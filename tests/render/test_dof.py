"""Depth of field (issue 27 item 3): ``--dof FOCUS_M:APERTURE`` and ``[render] dof``
(:mod:`piste.render.dof`): the CoC is the lens's, the pass blurs what is out of focus and keeps
what is in focus sharp, it comes closer to the accumulation reference (the mean of pinhole frames
over the lens disc) than the pinhole frame, the flags and the scene key reach the runtime."""

from __future__ import annotations

import numpy as np
import pytest

from piste.cli import build_parser, main
from piste.errors import ConfigError, PisteError
from piste.render.aa import AATarget
from piste.render.dof import coc_pixels, lens_cameras, parse_dof
from piste.world.camera import Camera
from piste.world.scene_file import loads_scene


def test_parse_dof():
    assert parse_dof("8:0.1") == (8.0, 0.1)
    for bad in ("8", "8:0.1:2", "0:0.1", "8:-1", "nan:0.1", "x:y"):
        with pytest.raises(ConfigError, match="--dof"):
            parse_dof(bad)


def test_coc_is_the_lens_cameras_parallax():
    """A point at depth z seen by the reference's pinhole eyes (re-aimed at the focus point) lands
    within coc_pixels(z) of where the centre eye sees it; the focus plane does not move."""
    cam = Camera(eye=np.array([0.0, 0.0, 2.0]), target=np.array([0.0, 50.0, 2.0]), fov_y=50.0, aspect=1.5)
    h = 400
    for z, expect_zero in ((10.0, True), (3.0, False), (60.0, False)):
        pt = np.array([0.0, z, 2.0, 1.0])
        spread = []
        for c in lens_cameras(cam, 10.0, 0.2, 24):
            clip = np.asarray(c.view_projection(), dtype=np.float64) @ pt
            spread.append(clip[:2] / clip[3] * h / 2.0)
        r = np.linalg.norm(np.asarray(spread), axis=1).max()
        coc = float(coc_pixels([z], 10.0, 0.2, 50.0, h)[0])
        if expect_zero:
            assert r < 0.05 and coc == 0.0
        else:
            assert abs(r - coc) < 0.03 * coc, (z, r, coc)


_VS = """
#version 330
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""
_FS = """
#version 330
uniform float u_near, u_far, u_z_left, u_z_right, u_w;
out vec4 c;
void main() {  // a 2-pixel checker; left half at depth u_z_left, right half at u_z_right
    ivec2 q = ivec2(gl_FragCoord.xy) / 2;
    float v = ((q.x + q.y) & 1) == 0 ? 0.9 : 0.1;
    c = vec4(v, v, v, 1.0);
    float z = gl_FragCoord.x < 0.5 * u_w ? u_z_left : u_z_right;
    float ndc = (u_far + u_near) / (u_far - u_near) - 2.0 * u_far * u_near / ((u_far - u_near) * z);
    gl_FragDepth = 0.5 * ndc + 0.5;
}
"""


def test_blurs_out_of_focus_and_keeps_focus_sharp(gl):
    import moderngl

    w, h = 128, 96
    cam = Camera(eye=np.zeros(3), target=np.array([0.0, 1.0, 0.0]), fov_y=60.0, near=0.5, far=4000.0)
    prog = gl.program(vertex_shader=_VS, fragment_shader=_FS)
    prog["u_near"].value, prog["u_far"].value = cam.near, cam.far
    prog["u_z_left"].value, prog["u_z_right"].value, prog["u_w"].value = 10.0, 80.0, float(w)
    vao = gl.vertex_array(prog, [])
    out = {}
    for name, dof in (("pinhole", None), ("dof", (10.0, 0.5))):
        t = AATarget(gl, (w, h), "off", dof=dof)
        try:
            t.camera = cam
            t.use()
            t.clear()
            gl.enable(moderngl.DEPTH_TEST)
            gl.depth_func = "1"
            vao.render(moderngl.TRIANGLES, vertices=3)
            gl.depth_func = "<"
            out[name] = t.read()[..., 0].astype(np.float64)
            again = t.read()[..., 0].astype(np.float64)  # a frame is post-processed once
            assert np.array_equal(again, out[name])
        finally:
            t.release()
    vao.release()
    prog.release()
    pin, dof = out["pinhole"], out["dof"]
    assert float(coc_pixels([80.0], 10.0, 0.5, 60.0, h)[0]) > 2.0  # the far half's CoC
    inner_left, inner_right = (slice(8, h - 8), slice(4, w // 2 - 8)), (slice(8, h - 8), slice(w // 2 + 8, w - 4))
    # in focus: the checker untouched; out of focus: its contrast gone towards the mean
    assert np.abs(dof[inner_left] - pin[inner_left]).max() <= 1.0
    assert dof[inner_right].std() < 0.25 * pin[inner_right].std()
    assert abs(dof[inner_right].mean() - pin[inner_right].mean()) < 3.0


# ---------------------------------------------------------------------------------------- the scene
SCENE = """\
name = "dof"
[terrain]
source = "default"
[lightmap]
res = 2
shadows = false
[visibility]
enabled = false
[render]
size = [192, 128]
dof = [6.0, 0.2]
[pack]
follow = "track"
start = 0.2
[auto_objects]
seed = 3
trees = 30
signs = 2
rocks = 3
rails = 1
[[cameras]]
name = "fly"
track = [0.2, 0.3]
"""


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle

    p = tmp_path_factory.mktemp("dof") / "dof.toml"
    p.write_text(SCENE)
    return load_bundle(build_scene(p).path)


def test_scene_error_against_accumulation_reference(gl, bundle):
    from piste.pipeline.preview import ScenePreview

    p = ScenePreview(bundle, ctx=gl, dof="off", object_lighting="dynamic")
    try:
        p.render(None, 0.5)
        cam = p.frame.scene.camera
        pin = p.render(cam, 0.5).astype(np.float64)
        ref = np.mean([p.render(c, 0.5) for c in lens_cameras(cam, 6.0, 0.2, 16)], axis=0)
    finally:
        p.release()
    q = ScenePreview(bundle, ctx=gl, object_lighting="dynamic")  # the scene file's dof
    try:
        assert q.dof == (6.0, 0.2) and isinstance(q.terrain.target, AATarget)
        dof = q.render(cam, 0.5).astype(np.float64)
    finally:
        q.release()
    e_pin, e_dof = np.abs(pin - ref).mean(), np.abs(dof - ref).mean()
    lens = np.abs(pin - ref).max(axis=-1) > 8  # where the lens changes the picture
    assert lens.mean() > 0.005
    assert e_dof < 0.7 * e_pin, (e_dof, e_pin)
    assert np.abs(dof - ref)[lens].mean() < 0.6 * np.abs(pin - ref)[lens].mean()


def test_scene_key_and_flags(gl, bundle, tmp_path, monkeypatch):
    assert bundle.manifest["render"]["dof"] == [6.0, 0.2]
    assert loads_scene("", tmp_path / "d.toml").render.dof is None
    with pytest.raises(PisteError, match=r"dof.*expected \[focus, aperture\]") as exc:
        loads_scene("[render]\ndof = [0.0, 0.1]\n", tmp_path / "bad.toml")
    assert "bad.toml" in str(exc.value)
    assert build_parser().parse_args(["render", "x.toml", "--dof", "12:0.05"]).dof == (12.0, 0.05)
    assert build_parser().parse_args(["view", "x.toml", "--dof", "3:0"]).dof == (3.0, 0.0)
    assert build_parser().parse_args(["demo"]).dof is None

    import piste.pipeline.preview as preview

    seen = {}
    monkeypatch.setattr(preview, "render_frames", lambda *a, **kw: seen.update(kw) or [{}])
    assert main(["render", str(bundle.path), "--dof", "5:0.1", "--out", str(tmp_path / "a.png")]) == 0
    assert seen["dof"] == (5.0, 0.1)


@pytest.mark.parametrize("value, what", [
    ("8", "expected FOCUS_M:APERTURE (e.g. 8:0.1), got '8'"),
    ("0:0.1", "expected a finite number in (0, 100000], got '0'"),
    ("8:-0.1", "expected a finite number in [0, 100], got '-0.1'"),
    ("8:inf", "expected a finite number in [0, 100], got 'inf'"),
])
def test_bad_dof_is_a_usage_error(value, what, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["render", "x.toml", "--dof", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert what in err[-1] and "--dof" in err[-1], err
