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
::

    LiveScene(path, bundle=None, cache_dir=None, size=None, camera=None, ctx=None, **preview_kw)
        ``.poll() -> bool`` (rebuilt and reloaded?), ``.render(t) -> image``, ``.last_error``, ``.last_build``
    run_headless(live, out_dir, frames=None, seconds=None, interval=0.1, log=None) -> list of PNG paths
    (log: called with each message; default the ``piste.pipeline.live`` logger at INFO)
    PreviewView(preview)           the fly-through window's view of a ScenePreview (piste.render.window)
    LiveView(live)                 the same for a LiveScene, reloaded in place
    run_window(live_factory, camera, size, **window_kw) -> state dict

``piste view SCENE`` (:mod:`piste.commands.view`) parses its flags and calls these with parameters.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from piste.errors import PisteError
from piste.pipeline.build import BuildResult, build_scene
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.preview import BundleScene, ScenePreview, camera_at
from piste.render import window
from piste.render.context import save_png
from piste.render.frame import DEFAULT_FOG_DENSITY
from piste.render.sky_pass import HORIZON
from piste.render.ssx_pass import SsxTerrainRenderer
from piste.render.window import SceneView, ViewFrame, ViewOptions, _wrap_screen
from piste.world.scene_file import load_scene

if TYPE_CHECKING:
    import moderngl

    from piste.pipeline.bundle_objects import Bundle
    from piste.world.camera import Camera

__all__ = ["LiveScene", "PreviewView", "LiveView", "run_headless", "run_window"]


def _stamp(paths: Iterable[str | os.PathLike[str]]) -> dict[str, tuple[int, int] | None]:
    out: dict[str, tuple[int, int] | None] = {}
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
    size, camera, ctx : passed to the preview (camera: a scene camera name; None: the first, or the
        chase camera of a ``[pack]`` scene)
    preview_kw : more :class:`~piste.pipeline.preview.ScenePreview` options (``face``, ``fog``)
    """

    def __init__(self, path: str | os.PathLike[str], bundle: str | os.PathLike[str] | None = None,
                 cache_dir: str | os.PathLike[str] | None = None, size: tuple[int, int] | None = None,
                 camera: str | None = None, ctx: moderngl.Context | None = None, **preview_kw: Any) -> None:
        self.path = Path(path)
        self.is_bundle = self.path.suffix.lower() == ".piste"
        self.bundle_path = Path(bundle) if bundle is not None else self.path.with_suffix(".piste")
        self.cache_dir = cache_dir
        self.camera = camera
        self.last_error: Exception | None = None
        self.last_build: BuildResult | None = None
        self.rebuilds = 0
        if self.is_bundle:
            self.bundle_path = self.path
            self._files: list[Path] = [self.path]
        else:
            self._build()
        self._stamps = _stamp(self._files)
        self.bundle = load_bundle(self.bundle_path)
        self.preview = ScenePreview(self.bundle, size=size, ctx=ctx, **preview_kw)

    def _build(self) -> BuildResult:
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

    def render(self, t: float = 0.0) -> np.ndarray:
        """The current frame ``(H, W, 3) uint8`` from the chosen camera."""
        chase = self.camera is None and self.preview.follow
        return cast(np.ndarray, self.preview.render(None if chase else camera_at(self.bundle, self.camera), t))  # read

    def release(self) -> None:
        self.preview.release()


def run_headless(live: LiveScene, out_dir: str | os.PathLike[str], frames: int | None = None, seconds: float | None = None,
                 interval: float = 0.1, log: Callable[[str], Any] | None = None) -> list[Path]:
    """Render ``out_dir/frame_0000.png`` now and one more frame after every change, until ``frames``
    frames were written or ``seconds`` passed (None: until interrupted).  Returns the PNG paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    log = log or logging.getLogger(__name__).info
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


class PreviewView:
    """The window's view of a :class:`~piste.pipeline.preview.ScenePreview` (:mod:`piste.render.window`):
    the bundle's scene drawn by the runtime straight into the window; V switches the bundle's
    visibility sets.  ``piste view`` of the default course uses it over the built default scene."""

    def __init__(self, preview: ScenePreview) -> None:
        self.preview = preview
        self.ctx: moderngl.Context | None = None
        self._hook()

    def _hook(self) -> None:
        self._vis = getattr(self.preview.terrain, "visibility", None)  # the bundle's sets (set_visibility)

    @property
    def bundle(self) -> Bundle:
        return self.preview.bundle

    @property
    def terrain(self) -> Any:
        return self.preview.terrain

    @property
    def riders(self) -> int:
        p = self.preview
        return len(p.scene.riders) if p.renderer is not None else 0

    @property
    def has_visibility(self) -> bool:
        return self.bundle.visibility is not None

    def attach(self, ctx: moderngl.Context | None) -> None:
        self.ctx = ctx
        _wrap_screen(self.preview.terrain, ctx)

    def poll(self) -> str | None:
        return None

    def draw(self, camera: Camera, t: float, opts: ViewOptions) -> ViewFrame:
        p = self.preview
        bundle = self.bundle
        p.terrain.set_visibility(self._vis if opts.visibility else None)
        if p.renderer is not None:
            if isinstance(p.scene, BundleScene):
                p.scene.visibility = bundle.visibility if opts.visibility else None
            return SceneView(p.renderer, fog=p.fog).draw(camera, t, opts)
        fog = DEFAULT_FOG_DENSITY if p.fog is None else p.fog
        if opts.lightmap_mode == "ps2" and isinstance(p.terrain, SsxTerrainRenderer):
            # an SSX level's ps2 picture blends its stored texels (Cs, As) as the GS does: the runtime's
            # render, not the general terrain draw's ps2 (which blends piste's own light map)
            frame = p.terrain.render(camera, lod=opts.lod, lightmap_mode="ps2", debug=opts.debug, read=False,
                                     fog="scene" if p.fog is None else p.fog)
        else:
            mesh = p.terrain.prepare(camera, lod=opts.lod)
            frame = p.terrain.draw(camera, mesh, lightmap_mode=opts.lightmap_mode, debug=opts.debug, read=False,
                                   fog="scene" if p.fog is None else p.fog)
        extra: dict[str, Any] = {}
        if p.objects is not None:
            vis = p.objects.objects.visible(camera.frustum_planes(), max_distance=camera.far, eye=camera.eye)
            if opts.visibility and bundle.visibility is not None and len(vis):
                keep = bundle.visibility.objects_at(camera.eye)
                if keep is not None:
                    vis = vis[keep[vis]]
            p.objects.draw(camera.view_projection(), camera.eye, vis, fog=(*HORIZON, fog) if fog else None)
            extra["objects"] = int(len(vis))
        return ViewFrame(camera, frame, extra)

    def release(self) -> None:
        self.preview.release()


class LiveView(PreviewView):
    """The window's view of a :class:`LiveScene`: a :class:`PreviewView` of its preview, rebuilt and
    reloaded in place when the scene's files change."""

    def __init__(self, live: LiveScene) -> None:
        self.live = live
        super().__init__(live.preview)

    def poll(self) -> str | None:
        """Rebuild/reload on change; a message for the log or None."""
        live = self.live
        if live.poll():
            self._hook()
            self.attach(self.ctx)
            return f"reloaded ({', '.join(live.last_build.rebuilt) if live.last_build else 'bundle'})"
        if live.last_error is not None:
            msg = f"error (keeping the last good scene): {live.last_error}"
            live.last_error = None
            return msg
        return None

    def release(self) -> None:
        self.live.release()


def run_window(live_factory: Callable[[moderngl.Context], LiveScene],
               camera: Camera | Callable[[LiveView], Camera] | None = None,
               size: tuple[int, int] = (640, 448), caption: str = "piste view", **kw: Any) -> dict[str, Any]:
    """Show a live scene in the fly-through window (:func:`piste.render.window.run_window`),
    reloading on change.  ``live_factory(ctx) -> LiveScene`` (the scene's GL objects live in the
    window's context); ``camera``: the start camera, or ``view -> camera``.  Returns the window's state dict."""
    holder: dict[str, LiveView] = {}

    def make(ctx: moderngl.Context) -> LiveView:
        holder["view"] = LiveView(live_factory(ctx))
        return holder["view"]

    return window.run_window(make, camera, size=size, caption=caption,
                             poll=lambda: holder["view"].poll() if "view" in holder else None, **kw)
