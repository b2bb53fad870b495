"""``piste view``: the fast in-game preview, an interactive window (pyglet + moderngl).

Every frame is rendered exactly as off-screen (terrain LOD, culling and tessellation follow the
camera; riders animate, skin and light; objects, projected shadows, specular, light maps, sky),
straight into the window's framebuffer, then the overlay (the talk's statistics table and a live
plot of the LOD mix and frame times) is blended over the top-left corner.

Keys (:data:`HELP`): W/S/A/D fly, Q/E down/up, Shift (held) 4x faster, arrows or mouse drag look,
F follow a rider / fly free, N next rider, L LOD colour view, M light map modulate / ps2, O LOD on/off,
V visibility sets on/off, H overlay, Space pause time, P screenshot, Esc quit.

Key handling: the window keeps its own set of held keys, fed by its own ``on_key_press`` /
``on_key_release`` handlers (pushed as one handler frame, so nothing replaces anything; unhandled
keys fall through to pyglet's defaults) and cleared when the window loses focus.

What is drawn comes from a *view* object (:class:`TerrainView` for the terrain alone,
:class:`SceneView` for a :class:`~piste.render.scene_renderer.SceneRenderer`; ``piste view SCENE``
adds a live-reloading one in :mod:`piste.pipeline.live`) made by a factory given the window's GL
context.  A view has ``riders`` (how many can be followed), ``has_visibility``,
``attach(ctx)`` (draw into the window), ``draw(camera, t, opts) -> ViewFrame``, ``release()``.

``run_window(..., state=PATH)`` writes a JSON record on exit (camera at start and end, frames,
riders and rider pixels drawn, fps) -- what the tests under Xvfb check; ``benchmark=N`` renders N
frames along a fixed path without input and returns the frame times.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.errors import RenderError
from piste.extras import environ
from piste.formats.atomic import atomic_path
from piste.render.context import Offscreen, save_png
from piste.render.overlay import OverlayPass, StatsHistory, overlay_image
from piste.world.camera import FlyCamera

if TYPE_CHECKING:
    import os

    import moderngl

    from piste.scene_data import Camera

__all__ = ["has_display", "run_window", "ViewOptions", "ViewFrame", "TerrainView", "SceneView", "HELP",
           "riders_in_view"]

HELP = ("W/S/A/D fly, Q/E down/up, Shift fast, arrows or mouse drag look, F follow a rider, N next rider, "
        "L LOD view, M modulate/ps2, O LOD on/off, V visibility on/off, H overlay, Space pause, P screenshot, Esc quit")


def has_display() -> bool:
    """Whether a window can be opened (an X11 or Wayland display on Linux; always on macOS/Windows)."""
    if sys.platform.startswith("linux"):
        return bool(environ("DISPLAY") or environ("WAYLAND_DISPLAY"))
    return True


@dataclass
class ViewOptions:
    """The toggles of the preview."""

    lightmap_mode: str = "modulate"
    debug: str | None = None
    lod: bool = True
    visibility: bool = True
    follow: int | None = None
    overlay: bool = True
    paused: bool = False


@dataclass
class ViewFrame:
    """What a view drew: the camera used, the terrain :class:`~piste.render.Frame`, extra counts."""

    camera: object
    terrain: object
    extra: dict = field(default_factory=dict)


def riders_in_view(camera: Camera, anchors: np.ndarray, radius: float = 1.2) -> int:
    """How many rider anchors ``(n, 3)`` (spheres of ``radius`` around their middles) meet the view frustum."""
    a = np.asarray(anchors, dtype=np.float64).reshape(-1, 3)
    if not len(a):
        return 0
    planes = np.asarray(camera.frustum_planes(), dtype=np.float64)  # (6, 4): n . x + d >= 0 inside
    centre = a + np.array([0.0, 0.0, 0.9])
    d = centre @ planes[:, :3].T + planes[:, 3]
    return int(np.count_nonzero((d >= -radius).all(axis=1)))


def _wrap_screen(renderer_terrain, ctx) -> None:
    if hasattr(renderer_terrain.target, "present"):  # anti-aliased (render.aa): drawn off-screen, shown by present()
        renderer_terrain.target.screen = ctx.screen
        return
    renderer_terrain.target.release()
    renderer_terrain.target = Offscreen.wrap(ctx, ctx.screen)


class TerrainView:
    """The terrain alone (a :class:`piste.render.TerrainRenderer`)."""

    riders = 0
    has_visibility = False

    def __init__(self, renderer):
        self.renderer = renderer
        self.terrain = renderer

    def attach(self, ctx: moderngl.Context) -> None:
        _wrap_screen(self.renderer, ctx)

    def draw(self, camera: Camera, t: float, opts: ViewOptions) -> ViewFrame:
        frame = self.renderer.render(camera, lod=opts.lod, lightmap_mode=opts.lightmap_mode, debug=opts.debug,
                                     read=False)
        return ViewFrame(camera, frame, {})

    def release(self) -> None:
        self.renderer.release()


class SceneView:
    """The completed scene (a :class:`piste.render.scene_renderer.SceneRenderer`): riders animate,
    objects, shadows, specular.  ``opts.follow`` chases that rider with the scene's chase camera;
    ``fog``: density per metre (None: the renderer's, sized to the scene)."""

    has_visibility = False

    def __init__(self, renderer, fog: float | None = None):
        self.renderer = renderer
        self.terrain = renderer.terrain
        self.fog = fog

    @property
    def riders(self) -> int:
        return len(self.renderer.scene.riders)

    def attach(self, ctx: moderngl.Context) -> None:
        _wrap_screen(self.renderer.terrain, ctx)

    def draw(self, camera: Camera, t: float, opts: ViewOptions) -> ViewFrame:
        scene = self.renderer.scene
        if opts.follow is not None:
            scene.follow = int(opts.follow) % max(len(scene.riders), 1)
        img = self.renderer.render(t, read=False, camera=None if opts.follow is not None else camera, lod=opts.lod,
                                   lightmap_mode=opts.lightmap_mode, debug=opts.debug, count_rider_pixels=True,
                                   fog=self.fog)
        cam = img.scene.camera
        s = img.stats
        extra = {"riders": s["riders"], "riders_in_view": riders_in_view(
                     cam, np.concatenate([img.scene.riders.anchor] + [f.riders.anchor for f in img.casts])),
                 "rider_models": s.get("rider_models", 1),
                 "rider_pixels": s.get("rider_pixels", 0), "rider_triangles": s["rider_triangles"],
                 "objects": s["objects_drawn"], "shadow_patches": s["shadow_patches"]}
        if self.renderer.tracer.enabled:  # --trace: the overlay's per-pass bars (piste.render.trace)
            extra["passes"] = dict(self.renderer.tracer.last)
        return ViewFrame(cam, img.terrain, extra)

    def release(self) -> None:
        self.renderer.release()


def _cam_record(cam) -> dict:
    return {"eye": [float(x) for x in cam.eye], "forward": [float(x) for x in cam.forward]}


# camera: a Camera or ``view -> Camera``, typed Any: pipeline.live.run_window passes its Optional camera through
def run_window(make_view: Callable[[moderngl.Context], Any], camera: Any,
               size: tuple[int, int] = (640, 448), caption: str = "piste view", opts: ViewOptions | None = None,
               frames: int | None = None, screenshot: str | os.PathLike[str] | None = None,
               state: str | os.PathLike[str] | None = None, exit_after: float | None = None,
               benchmark: int | None = None, benchmark_camera: Camera | Callable[[int], Camera] | None = None,
               poll: Callable[[], str | None] | None = None, log: Callable[[str], object] | None = None) -> dict:
    """Open a window, make the view (``make_view(ctx)``) and fly ``camera`` (a
    :class:`piste.world.camera.Camera`) through it.

    Parameters
    ----------
    make_view : ``ctx -> view`` (see the module docstring)
    camera : the start camera, or ``view -> camera``
    opts : the starting toggles (:class:`ViewOptions`)
    frames : quit after that many frames;  exit_after : quit after that many seconds
    screenshot : PNG written on quit (P writes ``out/view_<time>.png``)
    state : JSON written on quit: ``start``/``end`` camera (eye, forward), ``frames``, ``fps``,
        ``max_riders_in_view``, ``max_rider_pixels``, ``follow``, toggles
    benchmark : render this many frames (after 5 warm-up frames) with ``benchmark_camera(i)``
        (or one camera; None: chase rider 0 when the view has riders, else ``camera``) at t = i / 30 s,
        no input; the result has ``frame_ms`` (every frame's wall time, swap included)
    poll : called every 0.25 s (live reload); returns a message to print or None

    Returns the state dict.
    """
    try:
        import pyglet

        pyglet.options["debug_gl"] = False  # errors are checked by piste, once per frame
    except ImportError:
        raise RenderError("`piste view` needs pyglet: pip install 'piste[gl]' (or use `piste demo` for images)") from None
    import moderngl

    log = log or logging.getLogger(__name__).info
    opts = opts or ViewOptions()
    w, h = int(size[0]), int(size[1])
    try:
        config = pyglet.gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24,
                                  double_buffer=True)
        # hidden until the view is built and its first frame drawn: input sent to a visible window
        # before then would queue up and arrive all at once
        window = pyglet.window.Window(w, h, caption=caption, config=config, resizable=False, vsync=False,
                                      visible=False)
    except Exception as exc:
        raise RenderError(f"cannot open a {w}x{h} OpenGL 3.3 window: {exc}") from None
    key = pyglet.window.key
    ctx = moderngl.create_context()
    view = None
    overlay = None
    try:
        view = make_view(ctx)
        view.attach(ctx)
        if callable(camera):
            camera = camera(view)
        overlay = OverlayPass(ctx)
        fly = FlyCamera.from_camera(camera)
        held: set = set()
        st: dict[str, Any] = {"quit": False, "frames": 0, "t": 0.0, "error": None, "max_riders_in_view": 0, "max_rider_pixels": 0,
              "start": _cam_record(camera), "cam": camera, "overlay_at": 0.0, "moved_keys": []}
        history = StatsHistory(120)

        def fly_record() -> dict:
            return {"position": [float(x) for x in fly.position], "yaw": fly.yaw, "pitch": fly.pitch,
                    "forward": [float(x) for x in fly.forward]}

        st["fly_start"] = fly_record()  # where free flight began (updated when leaving the chase camera)

        def shot(path: str | os.PathLike[str] | None = None) -> Path:
            img = view.terrain.target.read()
            return save_png(path or f"out/view_{int(time.time())}.png", img[..., :3])

        def leave_follow() -> None:
            if opts.follow is not None:
                cam = st["cam"]
                fly.position = np.asarray(cam.eye, dtype=np.float64).copy()
                f = cam.forward
                fly.yaw = float(np.arctan2(f[0], f[1]))
                fly.pitch = float(np.arcsin(np.clip(f[2], -1.0, 1.0)))
                opts.follow = None
                st["fly_start"] = fly_record()

        def on_key_press(symbol: int, modifiers: int) -> bool | None:
            held.add(symbol)
            if symbol == key.ESCAPE:
                st["quit"] = True
            elif symbol == key.L:
                opts.debug = None if opts.debug == "lod" else "lod"
            elif symbol == key.M:
                opts.lightmap_mode = "ps2" if opts.lightmap_mode == "modulate" else "modulate"
            elif symbol == key.O:
                opts.lod = not opts.lod
            elif symbol == key.V:
                opts.visibility = not opts.visibility
            elif symbol == key.H:
                opts.overlay = not opts.overlay
            elif symbol == key.SPACE:
                opts.paused = not opts.paused
            elif symbol == key.F and view.riders:
                if opts.follow is None:
                    opts.follow = 0
                else:
                    leave_follow()
            elif symbol == key.N and view.riders:
                opts.follow = 0 if opts.follow is None else (opts.follow + 1) % view.riders
            elif symbol == key.P:
                log(f"wrote {shot()}")
            else:
                return None
            return pyglet.event.EVENT_HANDLED

        def on_key_release(symbol: int, modifiers: int) -> None:
            held.discard(symbol)

        def on_deactivate() -> None:
            held.clear()

        def on_mouse_drag(x: int, y: int, dx: int, dy: int, buttons: int, modifiers: int) -> None:
            leave_follow()
            fly.look(dx * 0.004, dy * 0.004)

        def on_close() -> bool:
            st["quit"] = True
            return pyglet.event.EVENT_HANDLED

        window.push_handlers(on_key_press=on_key_press, on_key_release=on_key_release, on_deactivate=on_deactivate,
                             on_mouse_drag=on_mouse_drag, on_close=on_close)

        def fly_update(dt: float) -> None:
            def k(*syms: int) -> float:
                return 1.0 if any(s in held for s in syms) else 0.0

            fast = 4.0 if k(key.LSHIFT, key.RSHIFT) else 1.0
            fwd, right, up = k(key.W) - k(key.S), k(key.D) - k(key.A), k(key.E) - k(key.Q)
            yaw, pitch = k(key.RIGHT) - k(key.LEFT), k(key.UP) - k(key.DOWN)
            if fwd or right or up or yaw or pitch:
                leave_follow()
                fly.move(fwd * fast, right * fast, up * fast, dt)
                fly.look(yaw * 1.5 * dt, pitch * 1.0 * dt)

        def draw_frame(cam_override: Camera | None = None) -> ViewFrame:
            cam = cam_override if cam_override is not None else fly.camera(w / h)
            ctx.error  # noqa: B018  pyglet's own calls may leave an error behind (Xvfb + llvmpipe): clear it
            vf = view.draw(cam, st["t"], opts)
            if hasattr(view.terrain.target, "present"):  # an anti-aliased frame (render.aa) to the screen
                view.terrain.target.present()
            st["cam"] = vf.camera
            if opts.overlay:
                overlay.draw((w, h))
            err = ctx.error
            if err != "GL_NO_ERROR":
                raise RenderError(f"OpenGL error {err} after drawing a frame of the view")
            return vf

        def header() -> str:
            tog = [opts.lightmap_mode, "LOD view" if opts.debug == "lod" else "", "" if opts.lod else "LOD off",
                   ("vis on" if opts.visibility else "vis off") if view.has_visibility else "",
                   f"rider {opts.follow}" if opts.follow is not None else "fly", "paused" if opts.paused else ""]
            return f"{history.fps():5.1f} fps  " + " ".join(x for x in tog if x)

        if benchmark:
            if benchmark_camera is None:
                if view.riders:
                    opts.follow = 0
                else:
                    benchmark_camera = camera
            cams = benchmark_camera if callable(benchmark_camera) else (lambda i: benchmark_camera)
            times = []
            window.set_visible(True)
            for i in range(int(benchmark) + 5):
                window.dispatch_events()
                t0 = time.perf_counter()
                st["t"] = i / 30.0
                vf = draw_frame(cams(i) if benchmark_camera is not None else None)
                window.flip()
                dt_ms = (time.perf_counter() - t0) * 1e3
                history.add(vf.terrain, dt_ms, vf.extra)
                if opts.overlay and i % 8 == 0:
                    overlay.update(overlay_image(history, header()))
                if i >= 5:
                    times.append(dt_ms)
                st["frames"] += 1
            st["frame_ms"] = times
            st["follow_used"] = opts.follow is not None
            st["end"] = _cam_record(st["cam"])
            return st

        draw_frame()
        window.flip()
        window.set_visible(True)
        t_start = last = time.perf_counter()
        last_poll = t_start
        while not st["quit"]:
            window.dispatch_events()
            if st["quit"] or window.has_exit:
                break
            now = time.perf_counter()
            dt = min(now - last, 0.25)
            last = now
            if not opts.paused:
                st["t"] += dt
            fly_update(dt)
            if poll is not None and now - last_poll > 0.25:
                last_poll = now
                msg = poll()
                if msg:
                    log(msg)
            vf = draw_frame()
            st["frames"] += 1
            ex = vf.extra
            st["max_riders_in_view"] = max(st["max_riders_in_view"], int(ex.get("riders_in_view", 0)))
            st["max_rider_pixels"] = max(st["max_rider_pixels"], int(ex.get("rider_pixels", 0)))
            if screenshot and frames is not None and st["frames"] >= frames:
                shot(screenshot)  # before the flip: the back buffer holds this frame
            window.flip()
            history.add(vf.terrain, (time.perf_counter() - now) * 1e3, ex)
            if opts.overlay and now - st["overlay_at"] > 0.25:
                st["overlay_at"] = now
                overlay.update(overlay_image(history, header()))
            window.set_caption(f"{caption}  {header()}")
            if frames is not None and st["frames"] >= frames:
                break
            if exit_after is not None and now - t_start > exit_after:
                break
        if screenshot and (frames is None or st["frames"] < frames):
            draw_frame()
            shot(screenshot)
        st["fps"] = history.fps()
        st["end"] = _cam_record(st["cam"])
        st["end_fly"] = fly_record()
        st["follow"] = opts.follow
        st["toggles"] = {"lightmap_mode": opts.lightmap_mode, "debug": opts.debug, "lod": opts.lod,
                         "visibility": opts.visibility, "overlay": opts.overlay}
        if state is not None:
            rec = {k: v for k, v in st.items() if k not in ("cam", "quit", "error", "overlay_at", "moved_keys")}
            with atomic_path(state) as tmp:
                tmp.write_text(json.dumps(rec, indent=1))
        return st
    finally:
        if overlay is not None:
            overlay.release()
        if view is not None:
            view.release()
        window.close()
