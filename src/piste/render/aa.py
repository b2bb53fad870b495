"""Anti-aliasing of a frame: multisampling (MSAA), FXAA, and the supersampled reference's filter.

The talk lists anti-aliasing first among what broadcast quality still needs; the PS2 drew aliased
edges.  Three ways here, each off by default (the picture is unchanged without them):

* ``msaa2|msaa4|msaa8``: the frame is drawn into multisampled colour + depth renderbuffers and
  resolved (a framebuffer blit averages each pixel's samples) when it is read.  The sample count is
  capped at the GL's ``GL_MAX_SAMPLES`` (Mesa llvmpipe: 4, so ``msaa8`` draws 4 there;
  :attr:`AATarget.samples` says what was drawn).
* ``fxaa``: the frame is drawn as usual into a colour texture, then a post pass (FXAA 3.11's quality
  variant, written from Lottes' description: a luma contrast test, the edge's orientation and side,
  a search along it for its ends, the pixel resampled across the edge by its distance to the nearer
  end, plus a sub-pixel blend) writes the anti-aliased picture.
* the reference, ``supersample N`` (:class:`piste.pipeline.preview.ScenePreview`): the frame drawn at
  N x N the size and box-filtered down (:func:`downsample`).

API
---
::

    AA_MODES                         "off", "msaa2", "msaa4", "msaa8", "fxaa"
    aa_samples(mode) -> int          samples a pixel the mode asks for (0: not multisampled)
    AATarget(ctx, size, mode)        an :class:`~piste.render.context.Offscreen` that anti-aliases on read()
    downsample(image, n) -> image    (H n, W n, C) uint8 -> (H, W, C) uint8, the mean of each n x n block
    edge_error(image, reference)     mean |difference| (0..255) on the reference's edge pixels, and their count
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError
from piste.render.context import Offscreen, load_shader, release_framebuffer
from piste.render.dof import DofPass

if TYPE_CHECKING:
    import moderngl

    from piste.world.camera import Camera

__all__ = ["AA_MODES", "aa_samples", "check_aa", "AATarget", "downsample", "edge_pixels", "edge_error"]

AA_MODES = ("off", "msaa2", "msaa4", "msaa8", "fxaa")


# FXAA 3.11, quality variant (Timothy Lottes, NVIDIA 2011), written from the algorithm's description:
# local contrast test on the 4 neighbours, horizontal or vertical edge from the 3x3 lumas, which side
# the edge lies on, a search along it (up to 8 steps, growing) for both ends, the pixel moved across
# the edge by its distance to the nearer end, and a sub-pixel term for pixel-sized features.
# "N" is texel row -1, "S" row +1 (the algorithm is symmetric: only the names follow its D3D origin).
_FXAA_FS = """
#version 330
uniform sampler2D u_color;
uniform vec2 u_rcp;  // 1 / size
out vec4 f_color;
const float EDGE_THRESHOLD = 0.125;
const float EDGE_THRESHOLD_MIN = 0.0625;
const float SUBPIX = 0.75;
const int STEPS = 8;
const float QUALITY[8] = float[8](1.0, 1.5, 2.0, 2.0, 2.0, 2.0, 4.0, 8.0);
float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }
float L(vec2 p) { return luma(textureLod(u_color, p, 0.0).rgb); }
float Lo(vec2 p, vec2 o) { return L(p + o * u_rcp); }  // (texel centres: no filtering)
void main() {
    vec2 pos = gl_FragCoord.xy * u_rcp;
    vec4 rgbM = textureLod(u_color, pos, 0.0);
    float lM = luma(rgbM.rgb);
    float lS = Lo(pos, vec2(0, 1)), lE = Lo(pos, vec2(1, 0)), lN = Lo(pos, vec2(0, -1)), lW = Lo(pos, vec2(-1, 0));
    float rMax = max(max(max(lS, lE), max(lN, lW)), lM);
    float rMin = min(min(min(lS, lE), min(lN, lW)), lM);
    float range = rMax - rMin;
    if (range < max(EDGE_THRESHOLD_MIN, rMax * EDGE_THRESHOLD)) { f_color = rgbM; return; }
    float lNW = Lo(pos, vec2(-1, -1)), lSE = Lo(pos, vec2(1, 1));
    float lNE = Lo(pos, vec2(1, -1)), lSW = Lo(pos, vec2(-1, 1));
    float lNS = lN + lS, lWE = lW + lE;
    float edgeHorz = abs(-2.0 * lW + lNW + lSW) + 2.0 * abs(-2.0 * lM + lNS) + abs(-2.0 * lE + lNE + lSE);
    float edgeVert = abs(-2.0 * lS + lSW + lSE) + 2.0 * abs(-2.0 * lM + lWE) + abs(-2.0 * lN + lNW + lNE);
    bool horz = edgeHorz >= edgeVert;  // a horizontal edge: the pixels across it are N and S
    float subA = 2.0 * (lNS + lWE) + (lNW + lSW + lNE + lSE);
    float l1 = horz ? lN : lW, l2 = horz ? lS : lE;
    float g1 = l1 - lM, g2 = l2 - lM;
    bool pair1 = abs(g1) >= abs(g2);
    float gradient = max(abs(g1), abs(g2));
    float stepLen = horz ? u_rcp.y : u_rcp.x;
    float lLocal;  // the mean luma of the pixel and its neighbour across the edge
    if (pair1) { stepLen = -stepLen; lLocal = 0.5 * (l1 + lM); } else { lLocal = 0.5 * (l2 + lM); }
    vec2 posB = pos;
    if (horz) posB.y += 0.5 * stepLen; else posB.x += 0.5 * stepLen;  // on the edge
    vec2 off = horz ? vec2(u_rcp.x, 0.0) : vec2(0.0, u_rcp.y);
    vec2 posN = posB - off * QUALITY[0], posP = posB + off * QUALITY[0];
    float endN = L(posN) - lLocal, endP = L(posP) - lLocal;
    float gScaled = 0.25 * gradient;
    bool doneN = abs(endN) >= gScaled, doneP = abs(endP) >= gScaled;
    for (int i = 1; i < STEPS && !(doneN && doneP); i++) {
        if (!doneN) { posN -= off * QUALITY[i]; endN = L(posN) - lLocal; doneN = abs(endN) >= gScaled; }
        if (!doneP) { posP += off * QUALITY[i]; endP = L(posP) - lLocal; doneP = abs(endP) >= gScaled; }
    }
    float dN = horz ? pos.x - posN.x : pos.y - posN.y;
    float dP = horz ? posP.x - pos.x : posP.y - pos.y;
    bool mLess = lM - lLocal < 0.0;
    bool good = (dN < dP) ? ((endN < 0.0) != mLess) : ((endP < 0.0) != mLess);
    float offEdge = good ? 0.5 - min(dN, dP) / (dN + dP) : 0.0;
    float subB = clamp(abs(subA / 12.0 - lM) / range, 0.0, 1.0);
    float subF = (-2.0 * subB + 3.0) * subB * subB;
    float o = max(offEdge, subF * subF * SUBPIX);
    vec2 p = pos;
    if (horz) p.y += o * stepLen; else p.x += o * stepLen;
    f_color = textureLod(u_color, p, 0.0);
}
"""


def aa_samples(mode: str) -> int:
    """Samples a pixel ``mode`` asks for: 2, 4, 8 for ``msaaN``, else 0."""
    check_aa(mode)
    return int(mode[4:]) if mode.startswith("msaa") else 0


def check_aa(mode: Any) -> str:
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

    ``dof``: ``(focus m, aperture m)`` adds the depth-of-field pass (:mod:`piste.render.dof`) before
    FXAA / after the MSAA resolve, for :attr:`camera` (set it before reading each frame).  A frame
    is resolved once: :meth:`use` marks a new one.
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], mode: str,
                 dof: tuple[float, float] | None = None) -> None:
        self.mode = check_aa(mode)
        super().__init__(ctx, size)  # the single-sampled output (what read() returns)
        self.samples = min(aa_samples(mode), int(ctx.max_samples)) if mode.startswith("msaa") else 0
        self.out: tuple[Any, Any, Any] = (self.fbo, self.color, self.depth)
        w, h = self.size
        # Any: moderngl types prog["name"] as a union of uniform, block, attribute and varying
        self._prog: Any = None
        self._vao: Any = None
        self.color: Any
        self.depth: Any
        if self.samples > 1:
            self.color = ctx.renderbuffer((w, h), 4, samples=self.samples)
            self.depth = ctx.depth_renderbuffer((w, h), samples=self.samples)
        elif mode == "fxaa":
            self.color = ctx.texture((w, h), 4)
            self.color.repeat_x = self.color.repeat_y = False
            self.depth = ctx.depth_renderbuffer((w, h))
            self._prog = ctx.program(vertex_shader=load_shader("fullscreen.vert.glsl"), fragment_shader=_FXAA_FS)
            self._prog["u_color"].value = 0
            self._prog["u_rcp"].value = (1.0 / w, 1.0 / h)
            self._vao = ctx.vertex_array(self._prog, [])
        if self.color is not self.out[1]:
            self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        self.screen: moderngl.Framebuffer | None = None
        self.dof = dof
        self.camera: Camera | None = None
        self._dof: DofPass | None = None
        self._fresh = True  # a frame drawn since the last resolve

    def use(self) -> None:
        super().use()
        self._fresh = True

    def resolve(self) -> None:
        """Write the anti-aliased frame into the output framebuffer (the draw target is kept)."""
        if not self._fresh:
            return
        self._fresh = False
        out = self.out[0]
        ctx = self.ctx
        if self.samples > 1:
            ctx.copy_framebuffer(out, self.fbo)
        if self.dof is not None and self.dof[1] > 0.0:
            if self.camera is None:
                raise ConfigError("depth of field: the frame's camera was not given (AATarget.camera)")
            if self._dof is None:
                self._dof = DofPass(ctx, self.size)
            src = out if self.samples > 1 else self.fbo
            self._dof.apply(src, self.fbo if self.mode == "fxaa" else out, self.camera, *self.dof)
        if self.mode != "fxaa":
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
        if self.ctx.fbo is self.out[0]:
            (self.ctx.screen or self.ctx.detect_framebuffer(0)).use()
        for obj in (self._vao, self._prog, self._dof):
            if obj is not None:
                obj.release()
        self._dof = None
        if self.fbo is not self.out[0]:
            release_framebuffer(self.ctx, self.fbo, self.color, self.depth)
        for obj in self.out:
            obj.release()
        self._vao = self._prog = None


def downsample(image: npt.ArrayLike, n: int) -> np.ndarray:
    """``(H n, W n, C) uint8`` -> ``(H, W, C) uint8``: the mean of each ``n x n`` block (a box filter),
    rounded."""
    img = np.asarray(image)
    n = int(n)
    if n == 1:
        return img
    h, w = img.shape[0] // n, img.shape[1] // n
    blocks = img[:h * n, :w * n].reshape(h, n, w, n, *img.shape[2:]).astype(np.float32)
    return np.rint(blocks.mean(axis=(1, 3))).astype(np.uint8)


def edge_pixels(reference: npt.ArrayLike, threshold: float = 24.0) -> np.ndarray:
    """``(H, W) bool``: pixels of ``reference`` ``(H, W, C) uint8`` whose luma gradient (the larger
    of the central differences across x and y, 0..255) is at least ``threshold`` (a strong edge)."""
    ref = np.asarray(reference, dtype=np.float32)
    luma = ref[..., :3] @ np.array([0.299, 0.587, 0.114], np.float32)
    gx = np.zeros_like(luma)
    gy = np.zeros_like(luma)
    gx[:, 1:-1] = np.abs(luma[:, 2:] - luma[:, :-2]) * 0.5
    gy[1:-1] = np.abs(luma[2:] - luma[:-2]) * 0.5
    return np.maximum(gx, gy) >= threshold


def edge_error(image: npt.ArrayLike, reference: npt.ArrayLike, threshold: float = 24.0) -> tuple[float, int]:
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
