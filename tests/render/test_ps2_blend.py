"""The two light-map modes against a numpy reference of the same 8-bit arithmetic.

``modulate`` computes Cd x CL in the shader; ``ps2`` draws the base texture Cd, then blends
(Cd - Cs) x As with FUNC_REVERSE_SUBTRACT (SRC_ALPHA, SRC_ALPHA), As = max(CL.r, CL.g, CL.b),
Cs = Cd - Cd x CL / As.  Cd and CL are read back from the renderer's own ``base`` and ``lightmap``
views of the same frame, so the reference sees exactly the texels the passes sampled.
"""

from __future__ import annotations

import numpy as np
import pytest

from piste.render import TerrainRenderer
from piste.world.camera import Camera

MAGENTA = (1.0, 0.0, 1.0, 1.0)


def ps2_reference(cd: np.ndarray, cl: np.ndarray) -> np.ndarray:
    """The PS2 light-map blend on 8-bit values: ``(Cd - Cs) x As`` with Cs and As quantised to
    8 bits as the blend unit sees them.  ``cd, cl (..., 3) uint8`` -> ``(..., 3) uint8``."""
    cdf = cd.astype(np.float64) / 255.0
    clf = cl.astype(np.float64) / 255.0
    a = clf.max(axis=-1, keepdims=True)
    cs = np.where(a > 0, cdf - cdf * clf / np.where(a > 0, a, 1.0), 0.0)
    cs8 = np.round(cs * 255.0)
    a8 = np.round(a * 255.0)
    return np.clip(np.round((cd.astype(np.float64) - cs8) * a8 / 255.0), 0, 255).astype(np.uint8)


def modulate_reference(cd: np.ndarray, cl: np.ndarray) -> np.ndarray:
    return np.round(cd.astype(np.float64) * cl.astype(np.float64) / 255.0).astype(np.uint8)


def test_reference_arithmetic_is_the_talks_identity():
    rng = np.random.default_rng(0)
    cd = rng.integers(0, 256, (20000, 3), dtype=np.uint8)
    cl = rng.integers(0, 256, (20000, 3), dtype=np.uint8)
    cl[:100] = 0  # As = 0
    cl[100:200] = cl[100:200, :1]  # grey light: Cs = 0
    diff = np.abs(ps2_reference(cd, cl).astype(int) - modulate_reference(cd, cl).astype(int))
    assert diff.max() <= 1
    assert (ps2_reference(cd[:100], cl[:100]) == 0).all()


def _coloured_textures():
    """A coloured base texture and a light map with strongly coloured, dark and black texels."""
    n = 64
    y, x = np.mgrid[0:n, 0:n] / n
    base = np.stack([0.55 + 0.45 * np.sin(2 * np.pi * x), 0.55 + 0.45 * np.cos(2 * np.pi * y),
                     0.5 + 0.5 * np.sin(2 * np.pi * (x + y))], axis=-1)
    base = np.concatenate([np.round(base * 255), np.full((n, n, 1), 255)], axis=-1).astype(np.uint8)
    h, w = 40, 40
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    light = np.stack([x, 1.0 - y, 0.5 + 0.5 * np.sin(6 * np.pi * x * y)], axis=-1) ** 1.5
    light[: h // 4, : w // 4] = 0.0  # unlit: As = 0
    return base, np.round(light * 255).astype(np.uint8)


@pytest.fixture(scope="module")
def frames(gl_context, grid_net):
    net = grid_net(4, 4, size=10.0, relief=4.0)
    net.lightmap_rect = np.repeat(np.array([[0.0125, 0.0125, 0.9875, 0.9875]], np.float32), len(net), 0)
    base, light = _coloured_textures()
    r = TerrainRenderer(net, size=(96, 64), ctx=gl_context, lightmap=light, base_texture=base)
    cam = Camera([20.0, -2.0, 24.0], [20.0, 17.0, 0.0])
    out = {}
    for name, kw in {
        "base": dict(debug="base"),
        "lightmap": dict(debug="lightmap"),
        "modulate": dict(lightmap_mode="modulate"),
        "ps2": dict(lightmap_mode="ps2"),
    }.items():
        out[name] = r.render(cam, sky=False, fog=0, clear=MAGENTA, **kw).image[..., :3]
    out["ps2_alpha"] = r.render(cam, sky=False, fog=0, clear=(1, 0, 1, 0.5), lightmap_mode="ps2").image[..., 3]
    r.release()
    assert gl_context.error == "GL_NO_ERROR"
    return out


def test_modes_match_the_numpy_reference(frames):
    cd, cl = frames["base"], frames["lightmap"]
    terrain = ~(cd == (255, 0, 255)).all(axis=-1)
    assert terrain.mean() > 0.5  # the net fills most of the frame
    assert (cl[terrain].max(axis=-1) == 0).any() and (cl[terrain].max(axis=-1) > 200).any()
    mod = frames["modulate"][terrain].astype(int)
    ps2 = frames["ps2"][terrain].astype(int)
    assert np.abs(mod - modulate_reference(cd[terrain], cl[terrain])).max() <= 1
    assert np.abs(ps2 - ps2_reference(cd[terrain], cl[terrain])).max() <= 2
    assert np.abs(ps2 - mod).max() <= 2
    # background untouched by both passes
    assert (frames["ps2"][~terrain] == (255, 0, 255)).all()


def test_ps2_pass_keeps_destination_alpha(frames):
    # the base pass writes alpha 1; the blended pass must not change it (separate alpha blending)
    terrain = ~(frames["base"] == (255, 0, 255)).all(axis=-1)
    assert (frames["ps2_alpha"][terrain] == 255).all()
    assert (np.abs(frames["ps2_alpha"][~terrain].astype(int) - 128) <= 1).all()


def test_agrees_with_the_gs_arithmetic_of_piste_lighting(frames):
    """The GL passes against ``piste.lighting.ps2``'s 8-bit GS model (half-bright, 128 = 1.0)."""
    gs = pytest.importorskip("piste.lighting.ps2")
    cd, cl = frames["base"], frames["lightmap"]
    terrain = ~(cd == (255, 0, 255)).all(axis=-1)
    cd, cl = cd[terrain], cl[terrain]
    cl_hb = np.round(cl.astype(np.float64) * 128.0 / 255.0).astype(np.uint8)
    cs, a = gs.ps2_source(cd, cl_hb)
    expect = gs.ps2_blend(cd, cs, a).astype(int)
    diff = np.abs(frames["ps2"][terrain].astype(int) - expect)
    assert diff.max() <= 3 and diff.mean() < 1.0
