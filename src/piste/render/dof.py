"""Depth of field (issue 27 item 3): a post pass that blurs each pixel by its circle of confusion.

A thin lens of radius ``aperture`` metres focused at ``focus`` metres images a point at view depth
``z`` as a disc of radius (pixels)::

    coc(z) = aperture * |1/z - 1/focus| * H / (2 tan(fov_y / 2))

which is exactly how far the point moves on screen when a pinhole eye moves by ``aperture`` across
the lens while the focus plane stays fixed -- the reference (:func:`lens_cameras`: the average of
many pinhole frames over the lens disc, each re-aimed at the focus point).

The pass (a gather): the depth buffer gives each pixel's view depth (from the camera's near/far)
and CoC (clamped at ``max_coc`` pixels); 48 samples on a golden-angle spiral over the largest CoC
each add their colour where their own disc covers the pixel, weighted by ``1 / (pi coc^2)`` (a
disc's light spread over its area); a sample behind the pixel spreads no wider than the pixel's own
CoC (sharp foreground edges keep the blurred background off them).

API
---
parse_dof("FOCUS_M:APERTURE") -> (focus, aperture)    metres; ConfigError naming what was expected
coc_pixels(z, focus, aperture, fov_y, height) -> (n,)  the CoC radius of view depths z, pixels
DofPass(ctx, size)                                     .apply(src_fbo, dst_fbo, camera, focus, aperture)
lens_cameras(camera, focus, aperture, n) -> [Camera]   the accumulation reference's pinhole eyes
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from piste.errors import ConfigError
from piste.render.context import load_shader

if TYPE_CHECKING:
    import moderngl
    import numpy.typing as npt

    from piste.world.camera import Camera

__all__ = ["parse_dof", "check_dof", "coc_pixels", "DofPass", "lens_cameras", "MAX_COC_FRACTION"]

#: the largest CoC the pass gathers, as a fraction of the image height (11 px at 448)
MAX_COC_FRACTION = 0.025
SAMPLES = 48


_FS = """
#version 330
uniform sampler2D u_color;
uniform sampler2D u_depth;
uniform vec2 u_rcp;        // 1 / size
uniform float u_near, u_far, u_focus;
uniform float u_scale;     // aperture * H / (2 tan(fov_y / 2)): pixels per (1/m)
uniform float u_max;       // largest CoC, pixels
const int N = %d;
out vec4 f_color;
float lin(float d) { float z = d * 2.0 - 1.0; return 2.0 * u_near * u_far / (u_far + u_near - z * (u_far - u_near)); }
float coc(float z) { return min(u_scale * abs(1.0 / z - 1.0 / u_focus), u_max); }
void main() {
    vec2 uv = gl_FragCoord.xy * u_rcp;
    float zc = lin(texture(u_depth, uv).r);
    float cc = coc(zc);
    float w0 = 1.0 / max(3.14159265 * cc * cc, 1.0);
    vec3 acc = texture(u_color, uv).rgb * w0;
    float wsum = w0;
    float area = 3.14159265 * u_max * u_max / float(N);  // of the disc, each sample's share
    for (int i = 0; i < N; i++) {
        float r = u_max * sqrt((float(i) + 0.5) / float(N));
        float a = float(i) * 2.39996323;
        vec2 p = uv + r * vec2(cos(a), sin(a)) * u_rcp;
        float zs = lin(texture(u_depth, p).r);
        float cs = coc(zs);
        if (zs > zc) cs = min(cs, cc);  // behind: no wider than this pixel's own blur
        float w = clamp(cs - r + 0.5, 0.0, 1.0) * min(area, 1.0) / max(3.14159265 * cs * cs, 1.0);
        acc += texture(u_color, p).rgb * w;
        wsum += w;
    }
    f_color = vec4(acc / wsum, 1.0);
}
""" % SAMPLES


def check_dof(focus: Any, aperture: Any, where: str = "dof") -> tuple[float, float]:
    """``(focus, aperture)`` as floats if focus is in (0, 1e5] m and aperture in [0, 100] m, else ConfigError."""
    try:
        f, a = float(focus), float(aperture)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected FOCUS_M:APERTURE numbers, got {focus!r}:{aperture!r}") from None
    if not (math.isfinite(f) and 0.0 < f <= 1e5 and math.isfinite(a) and 0.0 <= a <= 100.0):
        raise ConfigError(f"{where}: expected a focus distance in (0, 100000] m and an aperture (lens radius) "
                          f"in [0, 100] m, got {focus!r}:{aperture!r}")
    return f, a


def parse_dof(text: str, where: str = "--dof") -> tuple[float, float]:
    """``"FOCUS_M:APERTURE"`` -> ``(focus metres, aperture = lens radius metres)``, or ConfigError."""
    parts = str(text).split(":")
    if len(parts) != 2:
        raise ConfigError(f"{where}: expected FOCUS_M:APERTURE (e.g. 20:0.05), got {str(text)[:40]!r}")
    return check_dof(parts[0], parts[1], where)


def coc_pixels(z: npt.ArrayLike, focus: float, aperture: float, fov_y: float, height: int) -> np.ndarray:
    """CoC radius in pixels of view depths ``z`` ``(n,)`` metres (unclamped)."""
    scale = aperture * height / (2.0 * math.tan(math.radians(fov_y) / 2.0))
    return scale * np.abs(1.0 / np.asarray(z, dtype=np.float64) - 1.0 / focus)


class DofPass:
    """The depth-of-field post pass for frames of ``size = (W, H)`` (see the module docstring)."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        self.color = ctx.texture(self.size, 4)
        self.depth = ctx.depth_texture(self.size)
        self.depth.compare_func = ""
        for t in (self.color, self.depth):
            t.repeat_x = t.repeat_y = False
        import moderngl

        for t in (self.color, self.depth):  # whole texels: an in-focus pixel's nearest samples are itself
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        # Any: moderngl types prog["name"] as a union of uniform, block, attribute and varying
        self.prog = cast(Any, ctx.program(vertex_shader=load_shader("fullscreen.vert.glsl"), fragment_shader=_FS))
        self.prog["u_color"].value, self.prog["u_depth"].value = 0, 1
        self.prog["u_rcp"].value = (1.0 / self.size[0], 1.0 / self.size[1])
        self.vao = ctx.vertex_array(self.prog, [])

    def apply(self, src: moderngl.Framebuffer, dst: moderngl.Framebuffer, camera: Camera, focus: float, aperture: float) -> None:
        """Blur the frame in framebuffer ``src`` (colour + depth, single-sampled) into ``dst`` (colour;
        may be ``src``) for ``camera`` (its near, far, fov_y)."""
        import moderngl

        ctx = self.ctx
        ctx.copy_framebuffer(self.fbo, src)
        w, h = self.size
        p = self.prog
        p["u_near"].value, p["u_far"].value = float(camera.near), float(camera.far)
        p["u_focus"].value = float(focus)
        p["u_scale"].value = float(aperture * h / (2.0 * math.tan(math.radians(camera.fov_y) / 2.0)))
        p["u_max"].value = float(max(1.0, MAX_COC_FRACTION * h))
        was = ctx.fbo
        dst.use()
        ctx.viewport = (0, 0, w, h)
        ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        depth_mask = dst.depth_mask
        dst.depth_mask = False
        self.color.use(0)
        self.depth.use(1)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        dst.depth_mask = depth_mask
        ctx.enable(moderngl.DEPTH_TEST)
        if was is not None:
            was.use()

    def release(self) -> None:
        for obj in (self.vao, self.prog, self.fbo, self.color, self.depth):
            obj.release()


def lens_cameras(camera: Camera, focus: float, aperture: float, n: int = 32) -> list[Camera]:
    """``n`` pinhole cameras over a lens disc of radius ``aperture`` metres around ``camera``'s eye
    (a golden-angle spiral: even area coverage), each aimed at the point ``focus`` metres ahead on
    the axis: their mean frame is the depth-of-field reference."""
    eye = np.asarray(camera.eye, dtype=np.float64)
    fwd = np.asarray(camera.target, dtype=np.float64) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(camera.up, dtype=np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    focus_point = eye + fwd * float(focus)
    out = []
    for i in range(int(n)):
        r = aperture * math.sqrt((i + 0.5) / n)
        a = i * 2.39996323
        e = eye + r * (math.cos(a) * right + math.sin(a) * up)
        out.append(replace(camera, eye=e, target=focus_point))
    return out
