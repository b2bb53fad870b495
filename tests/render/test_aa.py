"""Anti-aliasing (issue 27 item 1): ``--aa off|msaa2|msaa4|msaa8|fxaa`` and ``--supersample N``
(:mod:`piste.render.aa`, :class:`piste.pipeline.preview.ScenePreview`): each mode renders, msaa4
and fxaa come closer to the supersampled reference on edges than no anti-aliasing, the flags and the
scene file's ``[render] aa`` reach the runtime, bad values are one-line usage errors."""

from __future__ import annotations

import numpy as np
import pytest

from piste.cli import build_parser, main
from piste.errors import ConfigError, PisteError
from piste.render.aa import AA_MODES, AATarget, aa_samples, downsample, edge_error, edge_pixels
from piste.render.context import Offscreen
from piste.world.scene_file import loads_scene

_VS = """
#version 330
in vec2 p;
void main() { gl_Position = vec4(p, 0.5, 1.0); }
"""
_FS = """
#version 330
out vec4 c;
void main() { c = vec4(1.0, 0.9, 0.6, 1.0); }
"""
# thin slanted triangles: edges at every angle, many partly covered pixels
_TRIS = np.array([[-0.9, -0.8], [0.85, -0.55], [-0.3, 0.9],
                  [0.2, 0.95], [0.95, 0.1], [0.9, 0.9]], dtype=np.float32)


def _draw(ctx, target) -> np.ndarray:
    import moderngl

    prog = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
    vbo = ctx.buffer(_TRIS.tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "2f", "p")])
    try:
        target.use()
        target.clear((0.05, 0.1, 0.3, 1.0))
        ctx.enable(moderngl.DEPTH_TEST)
        vao.render(moderngl.TRIANGLES)
        return target.read()[..., :3]
    finally:
        vao.release()
        vbo.release()
        prog.release()


@pytest.fixture(scope="module")
def triangles(gl_context):
    """``{mode: (H, W, 3) uint8}`` of the triangles at 96x64, plus "ref": drawn at 4x4 and box-filtered."""
    ctx = gl_context
    out = {}
    for mode in AA_MODES:
        t = AATarget(ctx, (96, 64), mode)
        try:
            out[mode] = _draw(ctx, t)
            out[mode + ":samples"] = t.samples
        finally:
            t.release()
    big = Offscreen(ctx, (96 * 4, 64 * 4))
    try:
        out["ref"] = downsample(_draw(ctx, big), 4)
    finally:
        big.release()
    return out


def test_each_mode_renders(gl, triangles):
    off = triangles["off"]
    assert off.shape == (64, 96, 3)
    assert len(np.unique(off.reshape(-1, 3), axis=0)) == 2  # aliased: background or triangle, nothing between
    for mode in ("msaa2", "msaa4", "msaa8", "fxaa"):
        img = triangles[mode]
        assert img.shape == off.shape
        assert np.count_nonzero(np.any(img != off, axis=-1)) > 20, mode  # edge pixels changed
        # away from edges (2 pixels and more: FXAA's reach) the picture is the same
        near = edge_pixels(triangles["ref"], 1.0)
        grown = near.copy()
        for dy in range(-2, 3):
            for dx in range(-2, 3):
                grown |= np.roll(near, (dy, dx), axis=(0, 1))
        far = ~grown
        assert far.mean() > 0.5
        assert np.array_equal(img[far], off[far]), mode
    assert triangles["msaa4:samples"] == min(4, gl.max_samples)
    assert triangles["msaa8:samples"] == min(8, gl.max_samples)
    assert triangles["fxaa:samples"] == 0 and triangles["off:samples"] == 0


def test_edge_error_below_off(gl, triangles):
    ref = triangles["ref"]
    e_off, n = edge_error(triangles["off"], ref)
    assert n > 100
    e_msaa, _ = edge_error(triangles["msaa4"], ref)
    e_fxaa, _ = edge_error(triangles["fxaa"], ref)
    assert e_msaa < 0.5 * e_off, (e_msaa, e_off)
    assert e_fxaa < e_off, (e_fxaa, e_off)


def test_downsample_is_a_box_filter():
    img = np.zeros((4, 6, 3), np.uint8)
    img[:2, :2] = 255
    img[2:, 4:] = (10, 20, 30)
    img[0, 2] = 100
    out = downsample(img, 2)
    assert out.shape == (2, 3, 3)
    assert out[0, 0].tolist() == [255] * 3 and out[1, 2].tolist() == [10, 20, 30] and out[0, 1].tolist() == [25] * 3
    assert downsample(img, 1) is img


def test_bad_modes():
    with pytest.raises(ConfigError, match="aa must be one of"):
        aa_samples("msaa16")
    with pytest.raises(ConfigError, match="aa must be one of"):
        AATarget(None, (8, 8), "ssaa")
    with pytest.raises(ConfigError, match="differ in shape"):
        edge_error(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 5, 3), np.uint8))


# ---------------------------------------------------------------------------------------- the scene
SCENE = """\
name = "aa"
[terrain]
source = "default"
[lightmap]
res = 2
shadows = false
[visibility]
enabled = false
[render]
size = [96, 64]
{aa}
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

    d = tmp_path_factory.mktemp("aa")
    p = d / "aa.toml"
    p.write_text(SCENE.format(aa='aa = "fxaa"'))
    return load_bundle(build_scene(p).path)


def test_scene_edge_error(gl, bundle):
    """The built scene (riders, objects, the track's edges): msaa4 and fxaa below off against
    supersample 4, and supersample 2 below them all."""
    from piste.pipeline.preview import ScenePreview

    def frame(aa="off", ss=1):
        p = ScenePreview(bundle, ctx=gl, aa=aa, supersample=ss, object_lighting="dynamic")
        try:
            return p.render(None, 0.5), p
        finally:
            p.release()

    ref, p = frame(ss=4)
    assert ref.shape == (64, 96, 3) and p.render_size == (384, 256)
    err = {m: edge_error(frame(m)[0], ref)[0] for m in ("off", "msaa4", "fxaa")}
    err["ss2"] = edge_error(frame(ss=2)[0], ref)[0]
    assert err["msaa4"] < 0.75 * err["off"], err
    assert err["fxaa"] < err["off"], err
    assert err["ss2"] < err["msaa4"], err


def test_scene_file_key_reaches_runtime(gl, bundle, tmp_path):
    from piste.pipeline.preview import ScenePreview

    assert bundle.manifest["render"]["aa"] == "fxaa"
    p = ScenePreview(bundle, ctx=gl)
    try:
        assert p.aa == "fxaa" and isinstance(p.terrain.target, AATarget) and p.terrain.target.mode == "fxaa"
    finally:
        p.release()
    p = ScenePreview(bundle, ctx=gl, aa="off")  # the flag wins over the scene file
    try:
        assert p.aa == "off" and not isinstance(p.terrain.target, AATarget)
    finally:
        p.release()
    assert loads_scene("", tmp_path / "d.toml").render.aa == "off"
    with pytest.raises(PisteError, match=r"aa.*expected \"off\", \"msaa2\"") as exc:
        loads_scene('[render]\naa = "msaa3"\n', tmp_path / "bad.toml")
    assert "bad.toml" in str(exc.value)
    with pytest.raises(ConfigError, match="supersample must be an integer in 1..8"):
        ScenePreview(bundle, ctx=gl, supersample=9)


def test_flags_parse_and_reach_runtime(gl, bundle, tmp_path, monkeypatch):
    args = build_parser().parse_args(["render", "x.toml", "--aa", "msaa4", "--supersample", "3"])
    assert args.aa == "msaa4" and args.supersample == 3
    args = build_parser().parse_args(["demo", "--aa", "fxaa"])
    assert args.aa == "fxaa" and args.supersample == 1
    assert build_parser().parse_args(["view", "x.toml", "--aa", "msaa2"]).aa == "msaa2"
    assert build_parser().parse_args(["render", "x.toml"]).aa is None  # the scene file's

    import piste.pipeline.preview as preview

    seen = {}

    def fake(bundle, camera=None, frames=1, size=None, **kw):
        seen.update(kw)
        return [{}]

    monkeypatch.setattr(preview, "render_frames", fake)
    assert main(["render", str(bundle.path), "--aa", "msaa8", "--supersample", "2",
                 "--out", str(tmp_path / "a.png")]) == 0
    assert seen["aa"] == "msaa8" and seen["supersample"] == 2


@pytest.mark.parametrize("argv, what", [
    (["render", "x.toml", "--aa", "msaa16"], "invalid choice: 'msaa16'"),
    (["render", "x.toml", "--supersample", "0"], "expected an integer in [1, 8], got '0'"),
    (["demo", "--supersample", "2.5"], "expected an integer in [1, 8], got '2.5'"),
    (["view", "x.toml", "--supersample", "2"], "unrecognized arguments: --supersample"),
])
def test_bad_flags_are_usage_errors(argv, what, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert what in err[-1], err
