"""The fast preview: watch a scene's source files, rebuild what changed, reload the running view.

:class:`LiveScene` polls the modification stamps of every file the scene reads (the TOML, the
terrain source, glTF files with their buffers and textures: :meth:`SceneFile.source_files`).  On a
change it rebuilds with the step cache -- only the steps whose inputs changed run (a light edited
in Blender re-bakes the light map and the object colours; the terrain fit, characters and
visibility come from the cache) -- and swaps the new bundle into the running
:class:`~piste.pipeline.preview.ScenePreview`.  A scene file with a mistake leaves the last good
bundle on screen and reports the error.

``piste view SCENE --headless --out DIR`` renders ``DIR/frame_0000.png`` at start and one more frame
per change (:func:`run_headless`); without ``--headless`` and with a display, a window shows the scene
and reloads in place (:func:`run_window`).

API
---
LiveScene(path, bundle=None, cache_dir=None, size=None, camera=None, ctx=None)
    ``.poll() -> bool`` (rebuilt and reloaded?), ``.render(t) -> image``, ``.last_error``, ``.last_build``
run_headless(live, out_dir, frames=None, seconds=None, interval=0.1, log=print) -> list of PNG paths
add_scene_arguments(parser), run_view(args)    the ``piste view SCENE`` hook (see commands/view.py)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from piste.errors import PisteError
from piste.extras import require

__all__ = ["LiveScene", "run_headless", "run_window", "add_scene_arguments", "run_view"]


def _stamp(paths) -> dict:
    out = {}
    for p in paths:
        try:
            st = Path(p).stat()
            out[str(p)] = (st.st_mtime_ns, st.st_size)
        except OSError:
            out[str(p)] = None
    return out


class LiveScene:
    """A scene (``.toml``) or bundle (``.piste``) kept up to date with its files.

    Parameters
    ----------
    path : the scene or bundle
    bundle : where to write the built bundle (default: the scene with suffix ``.piste``)
    cache_dir : build cache (default ``.piste-cache`` beside the scene)
    size, camera, ctx : passed to the preview (camera: a scene camera name)
    """

    def __init__(self, path, bundle=None, cache_dir=None, size=None, camera: str | None = None, ctx=None):
        from piste.formats.bundle import load_bundle
        from piste.pipeline.preview import ScenePreview

        self.path = Path(path)
        self.is_bundle = self.path.suffix.lower() == ".piste"
        self.bundle_path = Path(bundle) if bundle is not None else self.path.with_suffix(".piste")
        self.cache_dir = cache_dir
        self.camera = camera
        self.last_error: Exception | None = None
        self.last_build = None
        self.rebuilds = 0
        if self.is_bundle:
            self.bundle_path = self.path
            self._files = [self.path]
        else:
            self._build()
        self._stamps = _stamp(self._files)
        self.bundle = load_bundle(self.bundle_path)
        self.preview = ScenePreview(self.bundle, size=size, ctx=ctx)

    def _build(self):
        from piste.pipeline.build import build_scene
        from piste.world.scene_file import load_scene

        try:
            scene = load_scene(self.path)
            self._files = scene.source_files()
        except PisteError:
            self._files = getattr(self, "_files", [self.path.resolve()])
            raise
        self.last_build = build_scene(scene, out=self.bundle_path, cache_dir=self.cache_dir)
        return self.last_build

    def changed(self) -> bool:
        return _stamp(self._files) != self._stamps

    def poll(self) -> bool:
        """Rebuild and reload if a source file changed.  Returns True when a new bundle is on screen;
        a failed rebuild keeps the old one and sets :attr:`last_error`."""
        if not self.changed():
            return False
        from piste.formats.bundle import load_bundle

        self._stamps = _stamp(self._files)
        try:
            if not self.is_bundle:
                self._build()
                self._stamps = _stamp(self._files)
            bundle = load_bundle(self.bundle_path)
        except PisteError as exc:
            self.last_error = exc
            return False
        self.last_error = None
        self.bundle = bundle
        self.preview.reload(bundle)
        self.rebuilds += 1
        return True

    def render(self, t: float = 0.0):
        """The current frame ``(H, W, 3) uint8`` from the chosen camera."""
        from piste.pipeline.preview import camera_at

        return self.preview.render(camera_at(self.bundle, self.camera), t)

    def release(self) -> None:
        self.preview.release()


def run_headless(live: LiveScene, out_dir, frames: int | None = None, seconds: float | None = None,
                 interval: float = 0.1, log=None) -> list:
    """Render ``out_dir/frame_0000.png`` now and one more frame after every change, until ``frames``
    frames were written or ``seconds`` passed (None: until interrupted).  Returns the PNG paths."""
    from piste.render.context import save_png

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    log = log or (lambda msg: print(msg, file=sys.stderr))
    written = [save_png(out / "frame_0000.png", live.render())]
    log(f"wrote {written[-1]}")
    t0 = time.perf_counter()
    while (frames is None or len(written) < frames) and (seconds is None or time.perf_counter() - t0 < seconds):
        time.sleep(interval)
        tc = time.perf_counter()
        if live.poll():
            p = save_png(out / f"frame_{len(written):04d}.png", live.render())
            written.append(p)
            b = live.last_build
            what = f"rebuilt {', '.join(b.rebuilt) or 'nothing'}" if b is not None else "reloaded"
            log(f"change: {what}; wrote {p} ({time.perf_counter() - tc:.2f} s after the change was seen)")
        elif live.last_error is not None:
            log(f"error (keeping the last good scene): {live.last_error}")
            live.last_error = None
    return written


def run_window(live: LiveScene, frames: int | None = None, screenshot=None) -> int:
    """Show the scene in a window (pyglet), reloading on change; Esc quits.  Returns frames drawn."""
    pyglet = require("pyglet", "a window (`piste view`; or use --headless)")
    import numpy as np

    from piste.render.context import save_png

    w, h = live.preview.size
    window = pyglet.window.Window(w, h, caption=f"piste view {live.path.name}", vsync=False)
    state = {"frames": 0, "t0": time.perf_counter(), "img": None}

    def check(dt):
        if live.poll():
            print(f"reloaded ({', '.join(live.last_build.rebuilt) if live.last_build else 'bundle'})", file=sys.stderr)
        elif live.last_error is not None:
            print(f"error (keeping the last good scene): {live.last_error}", file=sys.stderr)
            live.last_error = None

    @window.event
    def on_draw():
        img = live.render(time.perf_counter() - state["t0"])
        state["img"] = img
        data = np.ascontiguousarray(img[::-1]).tobytes()
        pyglet.image.ImageData(w, h, "RGB", data).blit(0, 0)
        state["frames"] += 1
        if frames is not None and state["frames"] >= frames:
            pyglet.app.exit()

    @window.event
    def on_key_press(symbol, modifiers):
        if symbol == pyglet.window.key.ESCAPE:
            pyglet.app.exit()

    pyglet.clock.schedule_interval(check, 0.25)
    try:
        pyglet.app.run(interval=1 / 30)
    finally:
        pyglet.clock.unschedule(check)
        window.close()
    if screenshot and state["img"] is not None:
        save_png(screenshot, state["img"])
    return state["frames"]


# ----------------------------------------------------------------------------- the CLI hook
def add_scene_arguments(parser) -> None:
    """``piste view [SCENE] [--headless] [--camera NAME] [--watch-seconds S]`` (added to view's own)."""
    parser.add_argument("scene", nargs="?", help="a scene (.toml) or bundle (.piste) to preview live: rebuilt and "
                                                 "reloaded when its files change")
    parser.add_argument("--headless", action="store_true",
                        help="with SCENE: no window; render a frame to --out (a folder) at start and per change")
    parser.add_argument("--camera", help="with SCENE: the scene camera (default: the first)")
    parser.add_argument("--watch-seconds", type=float, help="with SCENE: stop watching after this many seconds")


def run_view(args) -> int:
    """``piste view SCENE``: the live preview (see the module docstring)."""
    from piste.render.window import has_display

    size = tuple(args.size) if getattr(args, "size", None) else None
    live = LiveScene(args.scene, size=size, camera=args.camera)
    try:
        if args.headless or not has_display():
            out = Path(args.out)
            if out.suffix.lower() == ".png":  # view's own default is a PNG path: use a folder beside it
                out = out.with_suffix("")
            if not args.headless:
                print("piste view: no display, so previewing headless into " + str(out), file=sys.stderr)
            files = run_headless(live, out, frames=args.frames, seconds=args.watch_seconds)
            print(f"{len(files)} frame(s) in {out}")
            return 0
        n = run_window(live, frames=args.frames, screenshot=args.out if args.frames else None)
        print(f"{n} frames")
        return 0
    finally:
        live.release()
