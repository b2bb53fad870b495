"""Passes that must not write depth (the PS2 second pass and fog, the SSX light-map blend, the
riders' specular, the shadow receivers, the sky) leave the depth buffer as they found it.

moderngl keeps the depth mask on the framebuffer: ``ctx.depth_mask = False`` sets only a Python
attribute and depth is still written (it was, in every one of these passes, until
:func:`piste.render.context.set_depth_write`)."""

from __future__ import annotations

import moderngl
import numpy as np

from piste.pipeline.ssx_synth import make_level
from piste.pipeline import load_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.preview import ScenePreview
from piste.pipeline.ssx_level import load_level
from piste.render import Offscreen, TerrainRenderer
from piste.render.context import set_depth_write
from piste.world.camera import Camera


def _depth(fbo) -> np.ndarray:
    return np.frombuffer(fbo.read(components=1, attachment=-1, dtype="f4"), dtype=np.float32).copy()


def test_set_depth_write_stops_and_restores_depth_writes(gl):
    target = Offscreen(gl, (8, 8))
    prog = gl.program(vertex_shader="#version 330\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }",
                      fragment_shader="#version 330\nout vec4 c; void main() { c = vec4(1.0); }")
    vbo = gl.buffer(np.array([-1, -1, 3, -1, -1, 3], dtype="f4").tobytes())
    vao = gl.vertex_array(prog, [(vbo, "2f", "p")])
    try:
        target.use()
        gl.enable(moderngl.DEPTH_TEST)
        gl.depth_func = "<"
        target.clear(depth=1.0)
        assert set_depth_write(gl, False) is True
        vao.render()
        assert (_depth(target.fbo) == 1.0).all()  # drawn (z = 0.5 passes "<") but not written
        assert set_depth_write(gl, True) is False
        vao.render()
        assert np.allclose(_depth(target.fbo), 0.5)
    finally:
        for obj in (vao, vbo, prog):
            obj.release()
        target.release()


def test_set_depth_write_without_a_bound_framebuffer():
    """A standalone context before any framebuffer is bound has none to mask (no error)."""
    from types import SimpleNamespace

    assert set_depth_write(SimpleNamespace(fbo=None), False) is True


def _watch(no_write: dict, monkeypatch):
    """Wrap ``VertexArray.render``: each draw with a program of ``no_write`` (program -> name) has
    the depth buffer read before and after; returns (names drawn, names that wrote depth)."""
    drawn, wrote = set(), set()
    render = moderngl.VertexArray.render

    def checked(vao, *args, **kwargs):
        name = no_write.get(vao.program)
        if name is None:
            return render(vao, *args, **kwargs)
        fbo = vao.ctx.fbo
        before = _depth(fbo)
        out = render(vao, *args, **kwargs)
        drawn.add(name)
        if fbo.depth_mask or not np.array_equal(_depth(fbo), before):
            wrote.add(name)
        return out

    monkeypatch.setattr(moderngl.VertexArray, "render", checked)
    return drawn, wrote


def test_ps2_second_pass_and_fog_leave_the_depth_buffer(gl, grid_net, monkeypatch):
    r = TerrainRenderer(grid_net(), size=(48, 32), ctx=gl)
    try:
        t = r.terrain
        no_write = {t.prog_ps2: "ps2 second pass", t.prog_fog: "fog pass", r.sky.prog: "sky"}
        drawn, wrote = _watch(no_write, monkeypatch)
        r.render(Camera([15.0, -8.0, 20.0], [15.0, 15.0, 0.0]), lightmap_mode="ps2", fog=0.02)
        monkeypatch.undo()
    finally:
        r.release()
    assert not wrote, f"these passes wrote depth: {sorted(wrote)}"
    assert drawn == set(no_write.values()), f"not drawn: {set(no_write.values()) - drawn}"


def test_ssx_blend_specular_shadow_and_sky_passes_leave_the_depth_buffer(tmp_path, gl, monkeypatch):
    make_level(rows=2, cols=3, seed=2).write(tmp_path, "LV")
    lo, hi = load_level(tmp_path / "LV.pbd").net.bounds
    cx, cy = (np.asarray(lo[:2]) + np.asarray(hi[:2])) / 2
    scene = tmp_path / "s.toml"
    scene.write_text(f'terrain = {{ ssx_pbd = "LV.pbd" }}\n[render]\nsize = [64, 48]\nlightmap_mode = "ps2"\n'
                     f'[[riders]]\nposition = [{cx}, {cy}]\n'
                     f'[[cameras]]\nname = "c"\neye = [{cx}, {cy - 9}, 10.0]\ntarget = [{cx}, {cy}, 3.0]\n')
    b = load_bundle(build_scene(scene, use_cache=False).path)
    p = ScenePreview(b, ctx=gl, shadows=True, specular=True)
    try:
        r = p.renderer
        r.characters.fold_specular = False  # the talk's separate additive specular pass (folded by default)
        no_write = {r.terrain.ssx_source.prog: "ssx light-map blend", r.terrain.sky.prog: "sky",
                    r.characters.prog_spec: "rider specular", r.shadows.receiver: "shadow receivers"}
        drawn, wrote = _watch(no_write, monkeypatch)
        p.render()
        monkeypatch.undo()
    finally:
        p.release()
    assert not wrote, f"these passes wrote depth: {sorted(wrote)}"
    assert drawn == set(no_write.values()), f"not drawn: {set(no_write.values()) - drawn}"
