"""Mip levels computed on the CPU (:func:`piste.render.textures.mip_chain`) and uploaded level by
level (:func:`piste.render.textures.mipmapped_texture`) instead of ``build_mipmaps`` at load: the
same levels as the GPU's ``glGenerateMipmap``, without its shader compile at start-up."""

from __future__ import annotations

import moderngl
import numpy as np
import pytest

from piste.errors import RenderError, ValidationError
from piste.render import Offscreen
from piste.render.character_pass import CharacterPass, specular_map
from piste.render.terrain_pass import TerrainPass
from piste.render.textures import MipLevels, mip_chain, mipmapped_texture, snow_texture

_VS = "#version 330\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }"
_FS = ("#version 330\nuniform sampler2D t; uniform int l; out vec4 c;\n"
       "void main() { c = texelFetch(t, ivec2(gl_FragCoord.xy), l); }")


def _levels(ctx, tex, w, h, components=4, top=None) -> list[np.ndarray]:
    """The mip levels of ``tex`` (``w x h``) down to 1 x 1 (or ``top``) read through a shader
    (``texelFetch``): moderngl's ``Texture.read`` knows only the levels ``build_mipmaps`` made."""
    prog = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
    vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], dtype="f4").tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "2f", "p")])
    out, level = [], 0
    try:
        while True:
            lw, lh = max(w >> level, 1), max(h >> level, 1)
            target = Offscreen(ctx, (lw, lh), depth=False)
            target.use()
            tex.use(0)
            prog["l"].value = level
            vao.render()
            out.append(target.read()[::-1, :, :components])  # row 0 = texture row 0
            target.release()
            if (lw == 1 and lh == 1) or level == top:
                return out
            level += 1
    finally:
        for obj in (vao, vbo, prog):
            obj.release()


def test_mip_chain_averages_pairs_horizontally_then_vertically():
    img = np.array([[[0], [1], [10], [20]],
                    [[3], [3], [30], [41]]], dtype=np.uint8)  # (2, 4, 1)
    levels = mip_chain(img)
    assert [lv.shape for lv in levels] == [(2, 4, 1), (1, 2, 1), (1, 1, 1)]
    # rows: (0+1+1)>>1 = 1, (3+3+1)>>1 = 3 -> (1+3+1)>>1 = 2;  (10+20+1)>>1 = 15, (30+41+1)>>1 = 36 -> 26
    assert levels[1][..., 0].tolist() == [[2, 26]]
    assert levels[2][..., 0].tolist() == [[14]]  # (2 + 26 + 1) >> 1, the last axis alone
    assert levels[0] is img or np.array_equal(levels[0], img)
    one = mip_chain(np.full((1, 8, 3), 7, np.uint8))
    assert [lv.shape for lv in one] == [(1, 8, 3), (1, 4, 3), (1, 2, 3), (1, 1, 3)]
    assert all((lv == 7).all() for lv in one)


def test_mip_chain_refuses_what_it_cannot_halve():
    with pytest.raises(ValidationError, match="powers of two"):
        mip_chain(np.zeros((6, 8, 4), np.uint8))
    with pytest.raises(ValidationError, match="uint8"):
        mip_chain(np.zeros((8, 8, 4), np.float32))


@pytest.mark.parametrize("shape", [(64, 128, 4), (32, 8, 4), (16, 16, 3), (8, 32, 1)])
def test_uploaded_levels_are_the_cpu_chain_and_the_gpus(gl, shape):
    img = np.random.default_rng(sum(shape)).integers(0, 256, shape, dtype=np.uint8)
    h, w, c = shape
    cpu, gpu = mipmapped_texture(gl, img), mipmapped_texture(gl, img, cpu=False)
    try:
        a, b = _levels(gl, cpu, w, h, c), _levels(gl, gpu, w, h, c)
    finally:
        cpu.release()
        gpu.release()
    chain = mip_chain(img)
    assert len(a) == len(chain) == int(np.log2(max(w, h))) + 1
    for level, (x, y, z) in enumerate(zip(a, b, chain)):
        assert np.array_equal(x, z), f"level {level} is not the uploaded chain"
        # the GPU's own filter (llvmpipe: the same bits; another driver's rounding within a step)
        assert np.abs(x.astype(int) - y.astype(int)).max() <= 1, f"level {level}"


def test_sides_not_powers_of_two_fall_back_to_the_gpu(gl):
    img = np.random.default_rng(5).integers(0, 256, (12, 20, 4), dtype=np.uint8)
    tex = mipmapped_texture(gl, img)
    try:
        levels = _levels(gl, tex, 20, 12)
    finally:
        tex.release()
    assert np.array_equal(levels[0], img) and levels[1].shape == (6, 10, 4)
    assert abs(float(levels[1].mean()) - float(img.mean())) < 8
    with pytest.raises(RenderError, match="uint8"):
        mipmapped_texture(gl, img.astype(np.float32))


def test_passes_build_no_mip_levels_on_the_gpu(gl, monkeypatch):
    """The terrain's base texture and a rider's textures get their levels from the CPU: no
    ``build_mipmaps`` (whose first call in a process compiles Mesa's blit shader) at set-up."""
    def refuse(self, *args, **kwargs):
        raise AssertionError("build_mipmaps called at set-up")

    monkeypatch.setattr(moderngl.Texture, "build_mipmaps", refuse)
    terrain = TerrainPass(gl)
    atlas = np.random.default_rng(7).integers(0, 256, (64, 64, 4), dtype=np.uint8)
    riders = CharacterPass(gl, [], atlas, max_riders=2)  # two recoloured copies and the specular map
    try:
        base = _levels(gl, terrain.base, 256, 256)
        want = mip_chain(snow_texture())
        assert all(np.array_equal(x, y) for x, y in zip(base, want))
        assert len(riders.textures) == 2
        spec = _levels(gl, riders.spec, 64, 64)
        assert all(np.array_equal(x, y) for x, y in zip(spec, mip_chain(specular_map(atlas))))
    finally:
        monkeypatch.undo()
        terrain.release()
        riders.release()


@pytest.mark.parametrize("size, levels", [((256, 64), 4), ((32, 32), 9), ((8, 2), 3), ((384, 128), 4)])
def test_mip_levels_drawn_on_the_gpu_are_the_cpu_chain(gl, size, levels):
    """A render target's levels redrawn by piste's shader (the shadow texture's case): the same
    levels as :func:`mip_chain` and ``build_mipmaps``, again after level 0 changes; the caller's
    framebuffer and viewport are kept."""
    w, h = size
    rng = np.random.default_rng(w + levels)
    tex = gl.texture((w, h), 4)
    ref = gl.texture((w, h), 4)
    screen = Offscreen(gl, (5, 3))
    mips = MipLevels(gl, tex, levels)
    try:
        assert mips.levels == min(levels, int(np.log2(max(w, h))))
        for _ in range(2):
            img = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
            tex.write(img.tobytes())
            ref.write(img.tobytes())
            screen.use()
            mips.build()
            assert gl.fbo is screen.fbo and tuple(gl.viewport) == (0, 0, 5, 3)
            ref.build_mipmaps(0, mips.levels)
            got = _levels(gl, tex, w, h, top=mips.levels)
            assert len(got) == mips.levels + 1
            if w & (w - 1) == 0:
                for level, (x, y) in enumerate(zip(got, mip_chain(img))):
                    assert np.array_equal(x, y), f"level {level}"
            for level, (x, y) in enumerate(zip(got, _levels(gl, ref, w, h, top=mips.levels))):
                assert np.abs(x.astype(int) - y.astype(int)).max() <= 1, f"level {level} (GPU's own filter)"
    finally:
        mips.release()
        for obj in (tex, ref):
            obj.release()
        screen.release()
    odd = gl.texture((12, 8), 4)
    try:
        assert MipLevels.supported(gl, odd, 2) and not MipLevels.supported(gl, odd, 3)
        with pytest.raises(RenderError, match="halve exactly 3 times"):
            MipLevels(gl, odd, 3)
    finally:
        odd.release()
