"""``piste view``: an interactive window (pyglet + moderngl) flying over the terrain.

The frame is rendered exactly as off-screen (LOD, cull and tessellation follow the camera every
frame), straight into the window's framebuffer.  Keys: W/S/A/D fly, Q/E down/up, Shift fast, arrows or mouse
drag look, L LOD view, M light-map mode (modulate / ps2), O LOD on/off, P screenshot, Esc quit.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from piste.errors import RenderError
from piste.extras import require

__all__ = ["has_display", "run_window"]


def has_display() -> bool:
    """Whether a window can be opened (an X11 or Wayland display on Linux; always on macOS/Windows)."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def run_window(net, camera, size=(640, 448), track=None, track_half_width: float = 16.0, lightmap="placeholder",
               lightmap_mode: str = "modulate", debug: str | None = None, lod: bool = True,
               frames: int | None = None, screenshot=None) -> int:
    """Open a window and fly ``camera`` (a :class:`piste.world.camera.Camera`) over ``net``.

    ``frames``: quit after that many frames (for tests and recordings); ``screenshot``: PNG path
    written when quitting (and by the P key).  Returns the number of frames drawn.
    """
    pyglet = require("pyglet", "a window (`piste view`)")
    pyglet.options["debug_gl"] = False  # errors are checked by piste, once per frame
    import moderngl

    from piste.render.context import Offscreen, save_png
    from piste.render.frame import TerrainRenderer
    from piste.world.camera import FlyCamera

    w, h = int(size[0]), int(size[1])
    try:
        config = pyglet.gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24,
                                  double_buffer=True)
        window = pyglet.window.Window(w, h, caption="piste view", config=config, resizable=False, vsync=False)
    except Exception as exc:
        raise RenderError(f"cannot open a {w}x{h} OpenGL 3.3 window: {exc}") from None
    ctx = moderngl.create_context()
    renderer = TerrainRenderer(net, size=(w, h), ctx=ctx, lightmap=lightmap, track=track,
                               track_half_width=track_half_width)
    # draw straight into the window's framebuffer
    renderer.target.release()
    renderer.target = Offscreen.wrap(ctx, ctx.screen)
    fly = FlyCamera.from_camera(camera)
    keys = pyglet.window.key.KeyStateHandler()
    window.push_handlers(keys)
    state = {"mode": lightmap_mode, "debug": debug, "lod": lod, "frames": 0, "last": time.perf_counter(),
             "fps": 0.0, "error": None}
    key = pyglet.window.key

    def shot(path=None):
        img = renderer.target.read()
        return save_png(path or f"out/view_{int(time.time())}.png", img[..., :3])

    @window.event
    def on_key_press(symbol, modifiers):
        if symbol == key.ESCAPE:
            pyglet.app.exit()
        elif symbol == key.L:
            state["debug"] = None if state["debug"] == "lod" else "lod"
        elif symbol == key.M:
            state["mode"] = "ps2" if state["mode"] == "modulate" else "modulate"
        elif symbol == key.O:
            state["lod"] = not state["lod"]
        elif symbol == key.P:
            print(f"wrote {shot()}")
        return pyglet.event.EVENT_HANDLED

    @window.event
    def on_mouse_drag(x, y, dx, dy, buttons, modifiers):
        fly.look(dx * 0.004, dy * 0.004)

    def update(dt):
        fast = 4.0 if keys[key.LSHIFT] or keys[key.RSHIFT] else 1.0
        fwd = (keys[key.W] - keys[key.S]) * fast
        right = (keys[key.D] - keys[key.A]) * fast
        up = (keys[key.E] - keys[key.Q]) * fast
        fly.move(fwd, right, up, dt)
        fly.look((keys[key.RIGHT] - keys[key.LEFT]) * 1.5 * dt, (keys[key.UP] - keys[key.DOWN]) * 1.0 * dt)

    @window.event
    def on_draw():
        # pyglet's own GL calls (event loop, buffer flips) can leave an error behind under some
        # drivers (seen: GL_INVALID_OPERATION with Xvfb + llvmpipe); clear it so that the
        # renderer's own check after drawing reports only errors of the frame itself
        state["pending"] = ctx.error
        try:
            frame = renderer.render(fly.camera(w / h), lod=state["lod"], lightmap_mode=state["mode"],
                                    debug=state["debug"], read=False)
        except Exception as exc:  # surface errors after the loop, not inside pyglet's handler
            state["error"] = exc
            pyglet.app.exit()
            return
        state["frames"] += 1
        now = time.perf_counter()
        state["fps"] = 0.9 * state["fps"] + 0.1 / max(now - state["last"], 1e-6)
        state["last"] = now
        k = frame.kind_counts
        window.set_caption(
            f"piste view  {state['fps']:.0f} fps  {frame.triangles} tris  4x4 {k[4]} 6x6 {k[6]} 8x8 {k[8]} glue {k[0]}  "
            f"[{state['mode']}{', LOD view' if state['debug'] == 'lod' else ''}{'' if state['lod'] else ', LOD off'}]"
        )
        if frames is not None and state["frames"] >= frames:
            if screenshot:
                shot(screenshot)
            pyglet.app.exit()

    pyglet.clock.schedule_interval(update, 1 / 120)
    try:
        pyglet.app.run(interval=0)
    finally:
        pyglet.clock.unschedule(update)
        renderer.release()
        window.close()
    if state["error"] is not None:
        raise state["error"]
    return state["frames"]
