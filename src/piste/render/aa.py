"""Anti-aliasing of a frame: multisampling (MSAA), FXAA, and the supersampled reference's filter.

The talk lists anti-aliasing first among what broadcast quality still needs; the PS2 drew aliased
edges.  Three ways here, each off by default (the picture is unchanged without them):

* ``msaa2|msaa4|msaa8``: the frame is drawn into multisampled colour + depth renderbuffers and
  resolved (a framebuffer blit averages each pixel's samples) when it is read.  The sample count is
  capped at the GL's ``GL_MAX_SAMPLES`` (Mesa llvmpipe: 4, so ``msaa8`` draws 4 there;
  :attr:`AATarget.samples` says what was drawn).
* ``fxaa``: the frame is drawn as usual into a colour texture, then a post pass (FXAA 3.11's console
  variant, written from Lottes' description: a luma range test, the edge direction from the four
  diagonal lumas, a two- and a four-tap blur along it, the four-tap one rejected where it leaves the
  local luma range) writes the anti-aliased picture.
* the reference, ``supersample N`` (:class:`piste.pipeline.preview.ScenePreview`): the frame drawn at
  N x N the size and box-filtered down (:func:`downsample`).

API
---
AA_MODES                         "off", "msaa2", "msaa4", "msaa8", "fxaa"
aa_samples(mode) -> int          samples a pixel the mode asks for (0: not multisampled)
AATarget(ctx, size, mode)        an :class:`~piste.render.context.Offscreen` that anti-aliases on read()
downsample(image, n) -> image    (H n, W n, C) uint8 -> (H, W, C) uint8, the mean of each n x n block
edge_error(image, reference)     mean |difference| (0..255) on the reference's edge pixels, and their count
"""

from __future__ import annotations

import numpy as np

from piste.errors import ConfigError
from piste.render.context import Offscreen

__all__ = ["AA_MODES", "aa_samples", "check_aa", "AATarget", "downsample", "edge_pixels", "edge_error"]

AA_MODES = ("off", "msaa2", "msaa4", "msaa8", "fxaa")

_VS = """
#version 330
void main() {  // one triangle over the whole viewport
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

# FXAA 3.11, console variant (Timothy Lottes, NVIDIA 2011), written from the algorithm's description
_FXAA_FS = """
#version 330
uniform sampler2D u_color;
uniform vec2 u_rcp;  // 1 / size
out vec4 f_color;
const float EDGE_SHARPNESS = 8.0;
const float EDGE_THRESHOLD = 0.125;
const float EDGE_THRESHOLD_MIN = 0.05;
float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }
void main() {
    vec2 uv = gl_FragCoord.xy * u_rcp;
    vec4 m = texture(u_color, uv);
    vec2 h = 0.5 * u_rcp;
    float lNW = luma(texture(u_color, uv + vec2(-h.x,  h.y)).rgb);
    float lNE = luma(texture(u_color, uv + vec2( h.x,  h.y)).rgb);
    float lSW = luma(texture(u_color, uv + vec2(-h.x, -h.y)).rgb);
    float lSE = luma(texture(u_color, uv + vec2( h.x, -h.y)).rgb);
    float lM = luma(m.rgb);
    float lMax = max(max(lNW, lNE), max(lSW, lSE));
    float lMin = min(min(lNW, lNE), min(lSW, lSE));
    lNE += 1.0 / 384.0;
    float lMaxM = max(lMax, lM), lMinM = min(lMin, lM);
    if (lMaxM - lMinM < max(EDGE_THRESHOLD_MIN, lMaxM * EDGE_THRESHOLD)) { f_color = m; return; }
    float a = lSW - lNE, b = lSE - lNW;
    vec2 dir1 = normalize(vec2(a + b, a - b));
    vec4 n1 = texture(u_color, uv - dir1 * u_rcp * 0.5);
    vec4 p1 = texture(u_color, uv + dir1 * u_rcp * 0.5);
    float dirAbsMinTimesC = min(abs(dir1.x), abs(dir1.y)) * EDGE_SHARPNESS;
    vec2 dir2 = clamp(dir1 / dirAbsMinTimesC, -2.0, 2.0);
    vec4 n2 = texture(u_color, uv - dir2 * u_rcp * 2.0);
    vec4 p2 = texture(u_color, uv + dir2 * u_rcp * 2.0);
    vec4 rgbyA = n1 + p1;
    vec4 rgbyB = (n2 + p2) * 0.25 + rgbyA * 0.25;
    float lB = luma(rgbyB.rgb);
    f_color = (lB < lMin || lB > lMax) ? rgbyA * 0.5 : rgbyB;
}
"""


def aa_samples(mode: str) -> int:
    """Samples a pixel ``mode`` asks for: 2, 4, 8 for ``msaaN``, else 0."""
    check_aa(mode)
    return int(mode[4:]) if mode.startswith("msaa") else 0


def check_aa(mode) -> str:
    """``mode`` if it is one of :data:`AA_MODES`, else :class:`ConfigError`."""
    if mode not in AA_MODES:
        raise ConfigError(f"aa must be one of {', '.join(AA_MODES)}; got {mode!r}")
    return mode


class AATarget(Offscreen):
    """An off-screen target of ``size = (W, H)`` that anti-aliases with ``mode`` when it is read.

    ``msaaN``: :attr:`fbo` holds multisampled RGBA8 + depth 24 renderbuffers (``samples`` each,
    capped at ``ctx.max_samples``); :meth:`resolve` blits them into a single-sampled framebuffer.
    ``fxaa``: :attr:`fbo` draws into an RGBA8 texture, :meth:`resolve` runs the FXAA pass into the
    output framebuffer.  :meth:`read` resolves, then reads ``(H, W, 4) uint8`` top row first.
    ``screen``: a window's framebuffer that :meth:`present` copies the resolved frame to.
    """

    def __init__(self, ctx, size: tuple[int, int], mode: str):
        self.mode = check_aa(mode)
        super().__init__(ctx, size)  # the single-sampled output (what read() returns)
        self.samples = min(aa_samples(mode), int(ctx.max_samples)) if mode.startswith("msaa") else 0
        self.out = self.fbo, self.color, self.depth
        w, h = self.size
        self._prog = self._vao = None
        if self.samples > 1:
            self.color = ctx.renderbuffer((w, h), 4, samples=self.samples)
            self.depth = ctx.depth_renderbuffer((w, h), samples=self.samples)
        elif mode == "fxaa":
            self.color = ctx.texture((w, h), 4)
            self.color.repeat_x = self.color.repeat_y = False
            self.depth = ctx.depth_renderbuffer((w, h))
            self._prog = ctx.program(vertex_shader=_VS, fragment_shader=_FXAA_FS)
            self._prog["u_color"].value = 0
            self._prog["u_rcp"].value = (1.0 / w, 1.0 / h)
            self._vao = ctx.vertex_array(self._prog, [])
        if self.color is not self.out[1]:
            self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        self.screen = None

    def resolve(self) -> None:
        """Write the anti-aliased frame into the output framebuffer (the draw target is kept)."""
        out = self.out[0]
        if self.fbo is out:
            return
        ctx = self.ctx
        if self.samples > 1:
            ctx.copy_framebuffer(out, self.fbo)
            return
        import moderngl

        was = ctx.fbo
        out.use()
        ctx.viewport = (0, 0, *self.size)
        ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.color.use(0)
        self._vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.enable(moderngl.DEPTH_TEST)
        if was is not None:
            was.use()

    def read(self) -> np.ndarray:
        """The anti-aliased colour buffer, ``(H, W, 4) uint8``, top row first (a fresh array)."""
        self.resolve()
        self.out[0].read_into(self._buf, components=4, alignment=1)
        return self._buf[::-1].copy()

    def present(self) -> None:
        """Resolve and copy the frame to :attr:`screen` (a window), if one is set."""
        if self.screen is None:
            return
        self.resolve()
        self.ctx.copy_framebuffer(self.screen, self.out[0])
        self.screen.use()  # (an overlay drawn next lands on the screen)

    def release(self) -> None:
        if self.ctx.fbo is self.fbo or self.ctx.fbo is self.out[0]:
            (self.ctx.screen or self.ctx.detect_framebuffer(0)).use()
        for obj in (self._vao, self._prog):
            if obj is not None:
                obj.release()
        if self.fbo is not self.out[0]:
            for obj in (self.fbo, self.color, self.depth):
                obj.release()
        for obj in self.out:
            obj.release()
        self._vao = self._prog = None


def downsample(image, n: int) -> np.ndarray:
    """``(H n, W n, C) uint8`` -> ``(H, W, C) uint8``: the mean of each ``n x n`` block (a box filter),
    rounded."""
    img = np.asarray(image)
    n = int(n)
    if n == 1:
        return img
    h, w = img.shape[0] // n, img.shape[1] // n
    blocks = img[:h * n, :w * n].reshape(h, n, w, n, *img.shape[2:]).astype(np.float32)
    return np.rint(blocks.mean(axis=(1, 3))).astype(np.uint8)


def edge_pixels(reference, threshold: float = 24.0) -> np.ndarray:
    """``(H, W) bool``: pixels of ``reference`` ``(H, W, C) uint8`` whose luma gradient (the larger
    of the central differences across x and y, 0..255) is at least ``threshold`` (a strong edge)."""
    ref = np.asarray(reference, dtype=np.float32)
    luma = ref[..., :3] @ np.array([0.299, 0.587, 0.114], np.float32)
    gx = np.zeros_like(luma)
    gy = np.zeros_like(luma)
    gx[:, 1:-1] = np.abs(luma[:, 2:] - luma[:, :-2]) * 0.5
    gy[1:-1] = np.abs(luma[2:] - luma[:-2]) * 0.5
    return np.maximum(gx, gy) >= threshold


def edge_error(image, reference, threshold: float = 24.0) -> tuple[float, int]:
    """Mean absolute difference (0..255 a channel, RGB) of ``image`` against ``reference``, both
    ``(H, W, C) uint8``, over the reference's edge pixels (:func:`edge_pixels`); and how many there are."""
    a, b = np.asarray(image), np.asarray(reference)
    if a.shape != b.shape:
        raise ConfigError(f"edge_error: image {a.shape} and reference {b.shape} differ in shape")
    mask = edge_pixels(b, threshold)
    n = int(np.count_nonzero(mask))
    if n == 0:
        return 0.0, 0
    d = np.abs(a[..., :3].astype(np.int16) - b[..., :3].astype(np.int16))[mask]
    return float(d.mean()), n
