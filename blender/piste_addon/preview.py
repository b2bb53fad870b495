"""Preview: ``piste view`` on the exported scene, re-exported as the artist works.

Start exports the scene and runs ``piste view SCENE.toml`` -- a window where there is a display,
else ``--headless --out FOLDER`` writing ``frame_NNNN.png`` per change, which the add-on loads
into the image "piste preview" (shown in an Image Editor).  Saving the .blend or a change in the
depsgraph (a transform, a mesh edit, a light or camera setting) marks the scene dirty; a timer
re-exports once the changes have paused for the debounce time (0.3 s by default).  The export
writes only the files whose bytes changed, and piste's live view (``piste.pipeline.live``)
rebuilds only the steps those files feed, so a change shows in about a second."""

from __future__ import annotations

import os
import time
from pathlib import Path

import bpy
from bpy.app.handlers import persistent

from . import exporter
from .runner import PisteNotFound, find_piste, start_piste

IMAGE = "piste preview"


class _State:
    proc = None
    frames_dir: Path | None = None
    dirty_since: float | None = None
    exporting = False
    last_frame: str | None = None
    exports = 0
    error: str | None = None
    log: Path | None = None


state = _State()


def _prefs(context):
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon is not None else None


def piste_exe(context) -> str:
    prefs = _prefs(context)
    return find_piste(prefs.piste_path if prefs is not None else "")


def running() -> bool:
    return state.proc is not None and state.proc.poll() is None


def mark_dirty(*_args) -> None:
    if not state.exporting:
        state.dirty_since = time.monotonic()


@persistent
def _on_depsgraph(scene, depsgraph=None):
    if state.exporting or depsgraph is None:
        return
    for u in depsgraph.updates:
        if u.is_updated_transform or u.is_updated_geometry or isinstance(u.id, (bpy.types.Light, bpy.types.Camera,
                                                                                  bpy.types.Scene, bpy.types.World)):
            mark_dirty()
            return


@persistent
def _on_save(*_args):
    mark_dirty()


def reexport(context=None) -> Path:
    context = context or bpy.context
    state.exporting = True
    try:
        path = exporter.export_scene(context)
        context.view_layer.update()  # the export's own selection / transform round trips: seen while guarded
    finally:
        state.exporting = False
        state.dirty_since = None
    state.exports += 1
    return path


def newest_frame() -> Path | None:
    if state.frames_dir is None or not state.frames_dir.is_dir():
        return None
    frames = sorted(state.frames_dir.glob("frame_*.png"))
    return frames[-1] if frames else None


def show_frame(path: Path):
    """Load ``path`` into the image "piste preview" and show it in any open Image Editor."""
    img = bpy.data.images.get(IMAGE)
    if img is None:
        img = bpy.data.images.load(str(path), check_existing=False)
        img.name = IMAGE
    else:
        img.filepath = str(path)
        img.reload()
    for window in getattr(bpy.context.window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type == "IMAGE_EDITOR":
                area.spaces.active.image = img
                area.tag_redraw()
    return img


def tick(force: bool = False) -> float | None:
    """One step of the preview loop (the timer's body): re-export when dirty and quiet for the
    debounce time, show a new headless frame, notice the view ending.  Returns the next interval."""
    try:
        debounce = bpy.context.scene.piste.preview_debounce
        if state.dirty_since is not None and (force or time.monotonic() - state.dirty_since >= debounce):
            reexport()
        frame = newest_frame()
        if frame is not None and str(frame) != state.last_frame:
            show_frame(frame)
            state.last_frame = str(frame)
    except Exception as exc:  # a bad export keeps the last good preview; said once
        state.error = str(exc)
        state.dirty_since = None
        print(f"piste preview: {exc}")
    if state.proc is not None and state.proc.poll() is not None:
        if state.proc.returncode not in (0, -15):  # said in the panel: piste's last line (its one-line error)
            state.error = f"piste view stopped: {_log_tail()}"
        stop()
        return None
    return 0.1


def _log_tail() -> str:
    try:
        lines = [ln for ln in Path(state.log).read_text(errors="replace").splitlines() if ln.strip()]
    except (OSError, TypeError):
        return "see preview.log"
    return lines[-1] if lines else "no output"


def start(context, headless: bool | None = None, frames: int | None = None, seconds: float | None = None):
    """Export, then run ``piste view`` on the scene; returns the process."""
    stop()
    exe = piste_exe(context)
    path = reexport(context)
    if headless is None:
        headless = bpy.app.background or not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                                              or os.name == "nt")
    r = context.scene.render
    size = (max(16, r.resolution_x * r.resolution_percentage // 100), max(16, r.resolution_y * r.resolution_percentage // 100))
    args = ["view", str(path), "--size", str(size[0]), str(size[1])]
    cam = context.scene.piste.preview_camera or context.scene.camera
    if cam is not None and cam.piste.role == "AUTO":
        args += ["--camera", cam.name]
    state.frames_dir = None
    if headless:
        state.frames_dir = path.parent / "preview"
        for old in state.frames_dir.glob("frame_*.png") if state.frames_dir.is_dir() else ():
            old.unlink()
        args += ["--headless", "--out", str(state.frames_dir)]
    if frames is not None:
        args += ["--frames", str(frames)]
    if seconds is not None:
        args += ["--watch-seconds", str(seconds)]
    state.last_frame, state.error, state.log = None, None, path.parent / "preview.log"
    state.proc = start_piste(exe, args, state.log)
    if _on_depsgraph not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(_on_depsgraph)
        bpy.app.handlers.save_post.append(_on_save)
    if not bpy.app.timers.is_registered(tick):
        bpy.app.timers.register(tick, first_interval=0.1, persistent=True)
    return state.proc


def stop() -> None:
    if state.proc is not None and state.proc.poll() is None:
        state.proc.terminate()
        try:
            state.proc.wait(timeout=5)
        except Exception:
            state.proc.kill()
    state.proc = None
    if _on_depsgraph in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_on_depsgraph)
    if _on_save in bpy.app.handlers.save_post:
        bpy.app.handlers.save_post.remove(_on_save)
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)


class PISTE_OT_preview(bpy.types.Operator):
    """Start piste's in-game preview of this scene (re-exported as you work)"""
    bl_idname = "piste.preview"
    bl_label = "Preview in piste"

    def execute(self, context):
        try:
            start(context)
        except PisteNotFound as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:
            self.report({"ERROR"}, f"piste preview: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, "piste preview started" + (f" (frames in {state.frames_dir})" if state.frames_dir else ""))
        return {"FINISHED"}


class PISTE_OT_preview_stop(bpy.types.Operator):
    """Stop piste's preview"""
    bl_idname = "piste.preview_stop"
    bl_label = "Stop preview"

    def execute(self, context):
        stop()
        return {"FINISHED"}


CLASSES = (PISTE_OT_preview, PISTE_OT_preview_stop)
