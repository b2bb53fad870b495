"""The shadow receivers' triangles are cut to each rider's shadow frustum (clip distances in
shadow_receiver.vert.glsl, GL_CLIP_DISTANCE0..5 on while the pass draws): far fewer fragments
than the whole terrain triangles (the vertex shader without its clip distances), the same picture
(the fragment shader leaves everything outside the frustum unchanged), and the clip planes are
off again afterwards."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from piste.render import Offscreen
from piste.render.context import load_shader
from piste.render.shadow_pass import ShadowPass, shadow_matrices


def _ground(half: float = 40.0):
    """Two big triangles of ground (z = 0), as one 'patch' of a terrain mesh."""
    pos = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]], np.float32)
    tris = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    return SimpleNamespace(patch_ids=np.array([0]), vertex_start=np.array([0, 4]), tri_start=np.array([0, 2]),
                           indices=tris, positions=pos)


def _unclipped(gl, sp):
    """``sp``'s receiver program with a vertex shader that writes no clip distances."""
    vs = load_shader("shadow_receiver.vert.glsl")
    cut = "\n".join(line for line in vs.splitlines() if "gl_ClipDistance" not in line)
    assert cut != vs
    p = gl.program(vertex_shader=cut, fragment_shader=load_shader("shadow_receiver.frag.glsl"))
    for name in ("u_shadow", "u_sunlit", "u_sun_rect"):
        p[name].value = sp.receiver[name].value
    return p


def _draw(gl, clip: bool):
    sun = np.array([0.3, 0.2, -1.0])
    from piste.world.objects import _icosphere

    v, f = _icosphere(2)
    caster = (v * 0.8 + [0.0, 0.0, 1.5]).astype(np.float32)
    sp = ShadowPass(gl, n_max=1, tile=128)
    if not clip:
        whole = _unclipped(gl, sp)
        sp.receiver.release()
        sp.receiver = whole
    target = Offscreen(gl, (160, 160))
    try:
        lvp = shadow_matrices(np.array([[0.0, 0.0, 1.5]]), 1.0, sun)
        sp.render_casters(caster[None], f.astype(np.uint32), lvp)
        ortho = np.array([[1 / 40.0, 0, 0, 0], [0, 1 / 40.0, 0, 0], [0, 0, -0.01, 0.0], [0, 0, 0, 1.0]])
        target.use()
        target.clear((1.0, 1.0, 1.0, 1.0))
        query = gl.query(samples=True)
        with query:
            sp.draw_receivers(_ground(), [np.array([0])], ortho, shade=(0.0, 0.0, 0.0), depth_bias=0.0)
        gl.finish()
        return target.read()[..., :3].astype(int), int(query.samples)
    finally:
        sp.release()
        target.release()


def test_receivers_rasterize_only_the_frustum(gl):
    img, samples = _draw(gl, True)
    whole, whole_samples = _draw(gl, False)
    assert whole_samples == 160 * 160  # the two triangles cover the target
    assert samples < 0.2 * whole_samples  # only the shadow frustum's footprint
    assert (img < 128).any(axis=-1).sum() > 5  # the shadow is there
    assert np.abs(img - whole).max() <= 1  # and the same as shading the whole triangles


def test_clip_planes_are_off_after_the_pass(gl):
    """A later pass whose vertex shader writes no clip distances draws everything."""
    _draw(gl, True)
    prog = gl.program(vertex_shader="#version 330\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }",
                      fragment_shader="#version 330\nout vec4 c; void main() { c = vec4(1.0); }")
    vbo = gl.buffer(np.array([-1, -1, 3, -1, -1, 3], dtype="f4").tobytes())
    vao = gl.vertex_array(prog, [(vbo, "2f", "p")])
    target = Offscreen(gl, (32, 32), depth=False)
    try:
        target.use()
        target.clear((0.0, 0.0, 0.0, 1.0))
        vao.render()
        assert (target.read()[..., 0] == 255).all()
    finally:
        for obj in (vao, vbo, prog):
            obj.release()
        target.release()
