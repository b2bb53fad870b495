"""``piste demo`` end to end at a small size: PNG, MP4 and the printed tables."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from piste.cli import main
from piste.world.object_lod import DEFAULT_LOD_PIXELS


def test_demo_writes_png_and_mp4(gl_context, piste_cache, tmp_path, capsys):
    png, mp4 = tmp_path / "out" / "demo.png", tmp_path / "out" / "demo.mp4"
    rc = main(["demo", "--size", "96", "64", "--frames", "2", "--out", str(png), "--video", str(mp4), "--no-progress"])
    assert rc == 0
    img = np.asarray(Image.open(png))
    assert img.shape == (64, 96, 3)
    assert img.std() > 5  # not a blank frame
    assert mp4.stat().st_size > 1000 and mp4.read_bytes()[4:8] == b"ftyp"
    import imageio.v2 as imageio

    with imageio.get_reader(mp4) as reader:
        frames = [f for f in reader]
    assert len(frames) == 2 and frames[0].shape == (64, 96, 3)
    out = capsys.readouterr().out
    assert "lighting baked" in out
    for text in ("4x4 patches", "average polygons per patch", "LOD + cull + tessellation", "draw", "fps",
                 "pipelined loop (wall time / frames)", "objects per LOD level", f"(error <= {DEFAULT_LOD_PIXELS:g} px)"):
        assert text in out
    assert sorted(p.name for p in png.parent.iterdir()) == ["demo.mp4", "demo.png"]  # no temp files


@pytest.mark.parametrize("extra", [["--lod", "off", "--lightmap", "ps2"], ["--debug", "lod"], ["--object-lod", "0"]])
def test_demo_options(gl_context, piste_cache, tmp_path, capsys, extra):
    png = tmp_path / "d.png"
    assert main(["demo", "--size", "64", "48", "--out", str(png), "--no-progress", "--lighting", "placeholder", *extra]) == 0
    out = capsys.readouterr().out
    assert png.exists()
    if "off" in extra:
        line = next(ln for ln in out.splitlines() if ln.startswith("8x8 patches"))
        assert "100.0 %" in line
    if "--object-lod" in extra:  # every object drawn with its full mesh: all at level 0
        line = next(ln for ln in out.splitlines() if "objects per LOD level" in ln)
        assert "(error <= 0 px)" in line
        counts = [int(x) for x in line.split("objects per LOD level")[1].split("(")[0].replace(",", " ").split()]
        assert counts[0] > 0 and sum(counts[1:]) == 0


def test_demo_is_the_built_default_scene_through_the_render_runtime(gl_context, piste_cache, tmp_path, capsys):
    """``piste demo`` builds the built-in default scene into the cache (once) and draws it with the
    runtime of ``piste render``: the full scene's first frame (six riders following the track, the
    placed objects: the scene file's ``[pack]`` and ``[auto_objects]``) is ``piste render``'s picture
    of the built bundle, pixel for pixel; the terrain fly-over is the terrain alone from its flight
    camera."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene, default_scene_path
    from piste.pipeline.preview import ScenePreview, camera_at

    demo_png, render_png = tmp_path / "demo.png", tmp_path / "render.png"
    assert main(["demo", "--objects", "baked", "--size", "64", "48", "--out", str(demo_png), "--no-progress"]) == 0
    assert "Characters: 6 riders" in capsys.readouterr().out
    bundle = default_scene_path(0).with_suffix(".piste")
    assert bundle.is_file() and bundle.parent == piste_cache / "scenes"
    again = build_default_scene(0)  # every step now comes from the build cache
    assert again.path == bundle and set(again.cached) >= {"terrain", "lightmap"}
    b_ = load_bundle(bundle)
    assert b_.manifest["pack"] == {"follow": "track", "start": 0.12}
    assert b_.manifest["auto_objects"]["seed"] == 0 and b_.manifest["auto_objects"]["trees"] == 220
    assert main(["render", str(bundle), "--size", "64", "48", "--out", str(render_png), "--quiet"]) == 0
    a, b = np.asarray(Image.open(demo_png)), np.asarray(Image.open(render_png))
    assert a.shape == b.shape == (48, 64, 3) and a.std() > 5
    assert np.array_equal(a, b)
    assert main(["demo", "--scene", "terrain", "--size", "64", "48", "--out", str(demo_png), "--no-progress"]) == 0
    p = ScenePreview(b_, size=(64, 48), ctx=gl_context, terrain_only=True)
    try:
        t = p.render(camera_at(b_, "flight"))
    finally:
        p.release()
    assert p.objects is None and np.array_equal(np.asarray(Image.open(demo_png)), t)


def test_demo_rejects_bad_arguments(tmp_path, capsys):
    assert main(["demo", "--size", "97", "64", "--video", str(tmp_path / "a.mp4"), "--out", str(tmp_path / "a.png")]) == 1
    assert "even width and height" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--lightmap", "multiply"])
