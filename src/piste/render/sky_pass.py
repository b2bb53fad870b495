"""A gradient sky drawn as one full-screen triangle behind everything."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from piste.render.context import load_shader, set_depth_write
from piste.render.textures import SUN_DIRECTION

if TYPE_CHECKING:
    import moderngl

__all__ = ["SkyPass", "HORIZON", "ZENITH"]

#: sky colours (linear 0..1 RGB): hazy horizon, deep blue zenith
HORIZON = (0.80, 0.86, 0.93)
ZENITH = (0.22, 0.42, 0.76)


class SkyPass:
    """Sky gradient by the view ray's elevation, with a soft glow around the sun."""

    def __init__(self, ctx: moderngl.Context, horizon: tuple[float, float, float] = HORIZON,
                 zenith: tuple[float, float, float] = ZENITH, sun: npt.ArrayLike = SUN_DIRECTION) -> None:
        self.ctx = ctx
        # Any: moderngl types prog["name"] as a union of uniform, block, attribute and varying
        self.prog = cast(Any, ctx.program(vertex_shader=load_shader("sky.vert.glsl"),
                                          fragment_shader=load_shader("sky.frag.glsl")))
        self.vao = ctx.vertex_array(self.prog, [])
        self.prog["u_horizon"].value = tuple(horizon)
        self.prog["u_zenith"].value = tuple(zenith)
        sun = np.asarray(sun, dtype=np.float64)
        self.prog["u_sun"].value = tuple(sun / np.linalg.norm(sun))

    def draw(self, view_projection: npt.ArrayLike) -> None:
        """Fill the pixels of the bound framebuffer that still hold the cleared depth (1.0) with
        the sky: draw it after the opaque geometry (depth test LEQUAL, no depth write), so it
        shades only what is left."""
        import moderngl

        inv = np.linalg.inv(np.asarray(view_projection, dtype=np.float64))
        self.prog["u_inv_vp"].write(inv.astype(np.float32).T.tobytes())
        self.ctx.disable(moderngl.BLEND)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.depth_func = "<="
        set_depth_write(self.ctx, False)
        try:
            self.vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            set_depth_write(self.ctx, True)
            self.ctx.depth_func = "<"

    def release(self) -> None:
        self.vao.release()
        self.prog.release()
