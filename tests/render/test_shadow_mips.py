"""The shadow texture's mip levels by compute dispatches (:class:`piste.render.shadow_pass.ComputeMips`,
two levels a dispatch, no framebuffer per level) are the levels of :func:`mip_chain` and of the
framebuffer path (:class:`piste.render.textures.MipLevels`) they replace where the GL has compute
shaders."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.render import Offscreen
from piste.render.shadow_pass import ComputeMips, ShadowPass
from piste.render.textures import MipLevels, mip_chain

_VS = "#version 330\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }"
_FS = ("#version 330\nuniform sampler2D t; uniform int l; out vec4 c;\n"
       "void main() { c = texelFetch(t, ivec2(gl_FragCoord.xy), l); }")


def _levels(ctx, tex, levels: int) -> list[np.ndarray]:
    """Levels ``0 .. levels`` of ``tex`` as ``(h, w, 4) uint8`` (row 0 = texture row 0), read
    through ``texelFetch`` (moderngl's ``Texture.read`` knows only levels it made)."""
    w, h = tex.size
    prog = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
    vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], dtype="f4").tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "2f", "p")])
    out = []
    try:
        for level in range(levels + 1):
            target = Offscreen(ctx, (max(w >> level, 1), max(h >> level, 1)), depth=False)
            target.use()
            tex.use(0)
            prog["l"].value = level
            vao.render()
            out.append(target.read()[::-1])
            target.release()
    finally:
        for obj in (vao, vbo, prog):
            obj.release()
    return out


def _needs_compute(gl):
    if gl.version_code < 430:
        pytest.skip("no OpenGL 4.3 compute shaders here (the framebuffer path is used)")


@pytest.mark.parametrize("size, levels", [((768, 128), 4), ((256, 64), 4), ((64, 32), 2)])
def test_compute_levels_are_the_cpu_chain(gl, size, levels):
    _needs_compute(gl)
    w, h = size
    rng = np.random.default_rng(w + h)
    tex = gl.texture((w, h), 4)
    mips = MipLevels(gl, tex, levels)  # allocates the levels
    cs = ComputeMips(gl, tex, levels)
    try:
        for _ in range(2):  # again after level 0 changes
            img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
            tex.write(img.tobytes())
            cs.build()
            got = _levels(gl, tex, levels)
            lv = img.astype(np.uint16)
            for level in range(1, levels + 1):  # mip_chain's arithmetic (its sides need not be powers of two here)
                lv = (lv[:, 0::2] + lv[:, 1::2] + 1) >> 1
                lv = (lv[0::2] + lv[1::2] + 1) >> 1
                assert np.array_equal(got[level], lv.astype(np.uint8)), f"level {level}"
            if w & (w - 1) == 0 and h & (h - 1) == 0:
                assert all(np.array_equal(x, y) for x, y in zip(got, mip_chain(img)))
    finally:
        cs.release()
        mips.release()
        tex.release()


def test_compute_levels_only_where_they_halve_evenly(gl):
    _needs_compute(gl)
    tex = gl.texture((48, 16), 4)
    f2 = gl.texture((64, 64), 4, dtype="f2")
    odd = gl.texture((40, 16), 4)
    try:
        assert ComputeMips.supported(gl, tex, 4) and ComputeMips.supported(gl, tex, 2)
        assert not ComputeMips.supported(gl, tex, 3)  # an odd count: the framebuffer path
        assert not ComputeMips.supported(gl, odd, 4)  # 40 does not halve 4 times
        assert not ComputeMips.supported(gl, f2, 2)
        with pytest.raises(RenderError, match="halve exactly 3 times"):
            ComputeMips(gl, tex, 3)
    finally:
        for t in (tex, f2, odd):
            t.release()


def test_shadow_pass_levels_equal_the_framebuffer_path(gl):
    """The casters' tiles mip-mapped by the dispatches: the same levels as MipLevels' passes."""
    _needs_compute(gl)
    sp = ShadowPass(gl, n_max=3, tile=128)
    try:
        assert sp._mips_cs is not None and sp.mip_levels == 4
        rng = np.random.default_rng(3)
        pos = rng.normal(0.0, 0.5, (3, 60, 3)).astype(np.float32)  # three scattered "riders"
        idx = np.arange(60, dtype=np.uint32).reshape(20, 3)
        lvp = np.stack([np.diag([0.8, 0.8, 0.1, 1.0])] * 3)
        got = {}
        for path in ("compute", "framebuffer"):
            cs = sp._mips_cs
            if path == "framebuffer":
                sp._mips_cs = None
            sp.render_casters(pos, idx, lvp)
            sp._mips_cs = cs
            got[path] = _levels(gl, sp.texture, sp.mip_levels)
        assert got["compute"][0].max() == 255  # something was drawn
        for level, (a, b) in enumerate(zip(got["compute"], got["framebuffer"])):
            assert np.array_equal(a, b), f"level {level}"
    finally:
        sp.release()


def test_releasing_a_shadow_pass_after_its_casters_leaves_the_context_usable(gl):
    """render_casters leaves the shadow framebuffer bound; releasing the pass must unbind it first,
    or moderngl re-binds the deleted framebuffer when it makes the next one (GL_INVALID_OPERATION:
    a renderer made after a shadowed one failed with "uploading a 256x256 texture's mip levels")."""
    sp = ShadowPass(gl, n_max=2, tile=128)
    pos = np.random.default_rng(5).normal(0.0, 0.5, (2, 30, 3)).astype(np.float32)
    sp.render_casters(pos, np.arange(30, dtype=np.uint32).reshape(10, 3), np.stack([np.eye(4)] * 2))
    assert gl.fbo is sp.fbo  # (what made the failure: the pass's framebuffer still bound)
    assert gl.error == "GL_NO_ERROR"
    sp.release()
    target = Offscreen(gl, (16, 16))
    try:
        assert gl.error == "GL_NO_ERROR"
    finally:
        target.release()
