"""The preview's on-screen overlay: the talk's statistics table and a small live plot.

:class:`StatsHistory` keeps the last frames' terrain counts and frame times; :func:`overlay_image`
draws the table (this window's figures beside the talk's) and a plot of the LOD mix (stacked 4x4 /
6x6 / 8x8 / glue shares, coloured as the LOD view colours them) with the frame time over it, into an
RGBA image with Pillow; :class:`OverlayPass` blends that image over the top-left corner of the
frame.  With ``--trace`` (frames whose ``extra`` carries ``passes``: :attr:`piste.render.trace.ChromeTracer.last`)
:func:`pass_bars` adds a bar per render pass: its GPU time (timer query) and its CPU issue time.  The image is redrawn a few times a second (text drawing costs ~2 ms), the blend every frame.

API
---
StatsHistory(n=120)            ``.add(frame, frame_ms, extra)``, ``.table_rows()``, arrays for the plot
overlay_image(history, header) -> (H, W, 4) uint8
OverlayPass(ctx)               ``.update(image)``, ``.draw(viewport_size)``, ``.release()``
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from piste.render.textures import LOD_COLORS
from piste.terrain.stats import TALK

if TYPE_CHECKING:
    import moderngl

    from piste.render.frame import Frame

__all__ = ["StatsHistory", "overlay_image", "OverlayPass", "LOD_COLOURS", "pass_bars"]

#: plot colours of the 4x4, 6x6, 8x8 and glue shares: the LOD view's own (piste.render.textures)
LOD_COLOURS = {k: tuple(int(c) for c in LOD_COLORS[k][:3]) for k in (4, 6, 8, 0)}


class StatsHistory:
    """The last ``n`` frames: terrain kind counts, triangles, patches, stage times and frame time."""

    def __init__(self, n: int = 120) -> None:
        self.n = int(n)
        self.frames: deque = deque(maxlen=self.n)

    def add(self, frame: Frame, frame_ms: float, extra: dict | None = None) -> None:
        """Record a :class:`piste.render.Frame` (terrain) and the wall time of the whole frame."""
        k = frame.kind_counts
        self.frames.append({
            "patches": frame.patches, "patches_total": frame.patches_total, "triangles": frame.triangles,
            4: k[4], 6: k[6], 8: k[8], 0: k[0], -1: k[-1],
            "tess_ms": float(frame.timings.get("tessellate", 0.0)), "frame_ms": float(frame_ms),
            **(extra or {}),
        })

    def __len__(self) -> int:
        return len(self.frames)

    def mix(self) -> np.ndarray:
        """``(k, 4)`` shares of 4x4, 6x6, 8x8 and glue patches per recorded frame (0..1)."""
        if not self.frames:
            return np.zeros((0, 4))
        a = np.array([[f[4], f[6], f[8], f[0] + f[-1]] for f in self.frames], dtype=np.float64)
        return a / np.maximum(a.sum(axis=1, keepdims=True), 1.0)

    def frame_ms(self) -> np.ndarray:
        """``(k,)`` wall milliseconds per recorded frame."""
        return np.array([f["frame_ms"] for f in self.frames], dtype=np.float64)

    def passes(self) -> dict:
        """``{pass: (cpu_ms, gpu_ms)}`` means over the recorded frames that carry them (``--trace``)."""
        got = [f["passes"] for f in self.frames if f.get("passes")]
        if not got:
            return {}
        names = list(dict.fromkeys(k for p in got for k in p))
        return {k: tuple(float(np.mean([p[k][j] for p in got if k in p])) for j in (0, 1)) for k in names}

    def fps(self) -> float:
        ms = self.frame_ms()
        return float(1e3 / np.median(ms)) if len(ms) and np.median(ms) > 0 else 0.0

    def table_rows(self) -> list[tuple[str, str, str]]:
        """The talk's statistics over the recorded frames: ``(label, this view, the talk)``."""
        if not self.frames:
            return []
        fs = self.frames
        p = sum(f["patches"] for f in fs)
        tris = sum(f["triangles"] for f in fs)
        pct = {k: 100.0 * sum(f[k] for f in fs) / max(p, 1) for k in (4, 6, 8, 0)}
        tess_s = sum(f["tess_ms"] for f in fs) / 1e3
        n = len(fs)
        rows = [
            ("patches drawn", f"{p / n:.0f} of {fs[-1]['patches_total']}", ""),
            ("4x4 / 6x6 / 8x8", f"{pct[4]:.0f} / {pct[6]:.0f} / {pct[8]:.0f} %",
             f"{TALK['pct_4']:.0f} / {TALK['pct_6']:.0f} / {TALK['pct_8']:.0f} %"),
            ("glue patches", f"{pct[0]:.1f} %", f"{TALK['pct_nonuniform']:.0f} %"),
            ("polygons", f"{tris / n:,.0f}", ""),
            ("polys per patch", f"{tris / max(p, 1):.2f}", f"{TALK['avg_polys_per_patch']:.2f}"),
            ("tessellation", f"{tess_s * 1e3 / n:.2f} ms", ""),
            ("throughput", f"{tris / tess_s / 1e6:.1f} Mpolys/s" if tess_s > 0 else "-", f"{TALK['mpolys_per_s']}"),
            ("no LOD: x polys", f"{98 * p / max(tris, 1):.2f}x", f"{TALK['no_lod_ratio']:.2f}x"),
        ]
        last = fs[-1]
        if "riders" in last:
            rows.append(("riders / tris", f"{last['riders']} / {last.get('rider_triangles', 0):,}", "6"))
        if "objects" in last:
            rows.append(("objects drawn", f"{last['objects']}", ""))
        return rows


def _font() -> Any:
    from PIL import ImageFont

    return ImageFont.load_default()


def overlay_image(history: StatsHistory, header: str, width: int = 300, plot_h: int = 48) -> np.ndarray:
    """The overlay ``(H, W, 4) uint8`` (straight alpha): ``header``, the table, the plot."""
    from PIL import Image, ImageDraw

    rows = history.table_rows()
    line = 12
    height = 6 + line * (2 + len(rows)) + plot_h + 8
    img = Image.new("RGBA", (width, height), (0, 0, 0, 150))
    d = ImageDraw.Draw(img)
    font = _font()
    y = 3
    d.text((4, y), header, fill=(255, 255, 255, 255), font=font)
    y += line
    col_b, col_c = 212, 222  # right edge of this view's column, left edge of the talk's

    def right(x: float, yy: float, text: str, fill: tuple[int, int, int, int]) -> None:
        d.text((x - d.textlength(text, font=font), yy), text, fill=fill, font=font)

    right(col_b, y, "view", (170, 200, 255, 255))
    d.text((col_c, y), "talk (PS2)", fill=(170, 200, 255, 255), font=font)
    y += line
    for a, b, c in rows:
        d.text((4, y), a, fill=(220, 220, 220, 255), font=font)
        right(col_b, y, b, (255, 255, 255, 255))
        d.text((col_c, y), c, fill=(170, 200, 255, 255), font=font)
        y += line
    # the plot: LOD mix as stacked columns, frame time as a white line (scale in the corner)
    x0, y0, pw = 4, y + 4, width - 8
    d.rectangle((x0, y0, x0 + pw, y0 + plot_h), fill=(0, 0, 0, 180))
    mix = history.mix()
    if len(mix):
        k = len(mix)
        cols = np.linspace(0, pw, history.n + 1)
        x_start = history.n - k
        for i in range(k):
            xa, xb = x0 + cols[x_start + i], x0 + cols[x_start + i + 1]
            top = y0 + plot_h
            for j, kind in enumerate((4, 6, 8, 0)):
                hgt = mix[i, j] * plot_h
                if hgt > 0:
                    d.rectangle((xa, top - hgt, max(xa, xb - 1), top), fill=(*LOD_COLOURS[kind], 255))
                top -= hgt
        ms = history.frame_ms()
        scale = max(float(np.percentile(ms, 95)) * 1.25, 1.0)
        pts = [(x0 + (cols[x_start + i] + cols[x_start + i + 1]) / 2, y0 + plot_h - min(ms[i] / scale, 1.0) * plot_h)
               for i in range(k)]
        if len(pts) > 1:
            d.line(pts, fill=(255, 255, 255, 255), width=1)
        d.text((x0 + 2, y0 + 1), f"frame ms (top {scale:.0f})", fill=(255, 255, 255, 255), font=font)
    passes = history.passes()
    if passes:
        bars = pass_bars(passes, width)
        out = np.zeros((height + bars.shape[0], width, 4), np.uint8)
        out[:height] = np.asarray(img)
        out[height:] = bars
        return out
    return np.asarray(img)


#: the bars' colours: GPU time (timer query), CPU time (issuing the pass)
_GPU_BAR, _CPU_BAR = (255, 170, 60, 255), (110, 170, 255, 255)


def pass_bars(passes: dict, width: int = 300, line: int = 12) -> np.ndarray:
    """``(H, W, 4) uint8``: one row per pass of ``{name: (cpu_ms, gpu_ms)}`` (means over the recent
    frames), its GPU time as an orange bar over its CPU issue time in blue, scaled to the longest."""
    from PIL import Image, ImageDraw

    font = _font()
    height = 4 + line * (1 + len(passes)) + 2
    img = Image.new("RGBA", (width, height), (0, 0, 0, 150))
    d = ImageDraw.Draw(img)
    d.text((4, 2), "pass ms:  GPU", fill=(*_GPU_BAR[:3], 255), font=font)
    d.text((4 + d.textlength("pass ms:  GPU ", font=font), 2), "/ CPU", fill=(*_CPU_BAR[:3], 255), font=font)
    top = max(max(max(c, g) for c, g in passes.values()), 1e-3)
    x0, x1 = 104, width - 44
    y = 2 + line
    for name, (cpu, gpu) in passes.items():
        d.text((4, y), name[:16], fill=(220, 220, 220, 255), font=font)
        d.rectangle((x0, y + 1, x0 + (x1 - x0) * gpu / top, y + 5), fill=_GPU_BAR)
        d.rectangle((x0, y + 6, x0 + (x1 - x0) * cpu / top, y + 9), fill=_CPU_BAR)
        d.text((x1 + 4, y), f"{gpu:5.2f}", fill=(255, 255, 255, 255), font=font)
        y += line
    return np.asarray(img)


_VS = """
#version 330
in vec2 in_pos;
uniform vec4 rect;      // x0, y0, x1, y1 in normalised device coordinates
out vec2 uv;
void main() {
    uv = in_pos;  // the image is uploaded bottom row first
    gl_Position = vec4(mix(rect.xy, rect.zw, in_pos), 0.0, 1.0);
}
"""
_FS = """
#version 330
in vec2 uv;
uniform sampler2D tex;
out vec4 colour;
void main() { colour = texture(tex, uv); }
"""


class OverlayPass:
    """Blends an RGBA image (straight alpha) over the top-left corner of the current framebuffer."""

    def __init__(self, ctx: moderngl.Context) -> None:
        import moderngl

        self.ctx = ctx
        # Any: moderngl types prog["name"] as a union of uniform, block, attribute and varying
        self.prog = cast(Any, ctx.program(vertex_shader=_VS, fragment_shader=_FS))
        quad = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype="f4")
        self.vbo = ctx.buffer(quad.tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f", "in_pos")])
        self.tex: moderngl.Texture | None = None
        self._moderngl = moderngl

    def update(self, image: np.ndarray) -> None:
        """Upload ``(H, W, 4) uint8`` (top row first)."""
        h, w = image.shape[:2]
        if self.tex is None or self.tex.size != (w, h):
            if self.tex is not None:
                self.tex.release()
            self.tex = self.ctx.texture((w, h), 4)
            self.tex.filter = (self._moderngl.NEAREST, self._moderngl.NEAREST)
        self.tex.write(np.ascontiguousarray(image[::-1]).tobytes())

    def draw(self, viewport_size: Sequence[int]) -> None:
        if self.tex is None:
            return
        mgl = self._moderngl
        vw, vh = viewport_size
        w, h = self.tex.size
        x1 = -1.0 + 2.0 * min(w, vw) / vw
        y0 = 1.0 - 2.0 * min(h, vh) / vh
        self.prog["rect"].value = (-1.0, y0, x1, 1.0)
        ctx = self.ctx
        ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)
        ctx.enable(mgl.BLEND)
        ctx.blend_equation = mgl.FUNC_ADD
        ctx.blend_func = (mgl.SRC_ALPHA, mgl.ONE_MINUS_SRC_ALPHA, mgl.ZERO, mgl.ONE)  # type: ignore[assignment]  # the stub lacks the 4-tuple form
        self.tex.use(0)
        self.vao.render(mgl.TRIANGLE_STRIP)
        ctx.disable(mgl.BLEND)
        ctx.blend_func = mgl.DEFAULT_BLENDING
        ctx.enable(mgl.DEPTH_TEST)

    def release(self) -> None:
        for o in (self.vao, self.vbo, self.prog, self.tex):
            if o is not None:
                o.release()
