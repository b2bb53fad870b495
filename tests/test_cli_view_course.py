"""``piste view`` without a scene file: the built default scene (the one ``piste demo`` draws)
through the runtime, :class:`piste.pipeline.preview.ScenePreview` (here its headless fallback,
which renders the frame the window would show; the window itself: tests/render/test_view_window.py)."""

from __future__ import annotations

import numpy as np
from PIL import Image

from piste.cli import main


def test_view_of_the_course_is_the_built_default_scene(gl_context, piste_cache, tmp_path, monkeypatch, capsys):
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview
    from piste.world.camera import track_camera

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    a, b, c = tmp_path / "a.png", tmp_path / "b.png", tmp_path / "c.png"
    base = ["view", "--size", "64", "48", "--lighting", "placeholder"]
    assert main(base + ["--terrain-only", "--start", "0.3", "--out", str(a)]) == 0
    bundle = load_bundle(build_default_scene(0).path)  # from the cache: the view built it
    p = ScenePreview(bundle, size=(64, 48), ctx=gl_context, lightmap="placeholder", terrain_only=True)
    try:
        ref = p.render(track_camera(bundle.centerline, 0.3, aspect=64 / 48))
    finally:
        p.release()
    assert np.array_equal(np.asarray(Image.open(a)), ref)
    # the full scene: --follow N chases rider N of the scene file's [pack]
    assert main(base + ["--follow", "0", "--out", str(b)]) == 0
    assert main(base + ["--follow", "3", "--out", str(c)]) == 0
    ib, ic = (np.asarray(Image.open(x)).astype(int) for x in (b, c))
    assert ib.std() > 5 and (np.abs(ib - ic).max(-1) > 30).sum() > 20
