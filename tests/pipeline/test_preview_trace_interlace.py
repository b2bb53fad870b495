"""The runtime's performance trace (ScenePreview(trace=)) and interlaced video (render_frames(interlace=))."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from piste.errors import ConfigError
from piste.pipeline.open_scene import open_source
from piste.pipeline.preview import ScenePreview, camera_at, render_frames
from piste.render.interlace import flicker, weave
from piste.render.trace import load_trace

PASSES = ("shadow casters", "terrain", "shadow receivers", "objects", "riders")
SIZE = (96, 64)


def _inside(kid, parent, slack_us=1e-3):
    return parent["ts"] - slack_us <= kid["ts"] and kid["ts"] + kid["dur"] <= parent["ts"] + parent["dur"] + slack_us


def test_the_trace_has_every_pass_in_every_frame_nested_in_it(small_scene, gl, tmp_path):
    b = open_source(str(small_scene(riders=True)), quiet=True, warm=True)
    path = tmp_path / "out" / "trace.json"
    render_frames(b, None, 3, size=SIZE, fps=30, ctx=gl, trace=path)
    data = load_trace(path)
    assert data["metadata"]["frames"] == 3
    assert data["metadata"]["gpu_timing"] in ("GL_TIME_ELAPSED", "glFinish")
    evs = [e for e in data["traceEvents"] if e["ph"] == "X"]
    for tid, cat in ((1, "pass"), (2, "gpu")):
        frames = sorted((e for e in evs if e["tid"] == tid and e["name"] == "frame"), key=lambda e: e["ts"])
        assert [f["args"]["frame"] for f in frames] == [0, 1, 2]
        for f in frames:
            kids = [e for e in evs if e["tid"] == tid and e["cat"] == cat and e["args"]["frame"] == f["args"]["frame"]]
            assert sorted(e["name"] for e in kids) == sorted(PASSES)
            assert all(_inside(e, f) for e in kids)
            if tid == 1:  # the CPU steps too
                steps = {e["name"] for e in evs if e["cat"] == "cpu" and e["args"]["frame"] == f["args"]["frame"]}
                assert {"plan", "scene update", "terrain LOD + cull + tessellate", "read back"} <= steps
                plan = next(e for e in evs if e["name"] == "plan" and e["args"]["frame"] == f["args"]["frame"])
                assert _inside(plan, f)
            else:  # GPU spans end to end, in pass order
                kids.sort(key=lambda e: e["ts"])
                assert [e["name"] for e in kids] == list(PASSES)


def test_tracing_changes_no_pixel(small_scene, gl, tmp_path):
    b = open_source(str(small_scene(riders=True)), quiet=True, warm=True)
    cam = camera_at(b, "main")
    images = []
    for trace in (None, tmp_path / "t.json"):
        p = ScenePreview(b, size=SIZE, ctx=gl, trace=trace)
        try:
            images.append(p.render(cam, 0.1))
        finally:
            p.release()
    assert np.array_equal(images[0], images[1])
    assert (tmp_path / "t.json").is_file()


def _first_frame(b, gl, tmp_path, name, **kw):
    png = tmp_path / f"{name}.png"
    render_frames(b, "main", 1, size=SIZE, fps=30, ctx=gl, first_png=png, **kw)
    return np.asarray(Image.open(png).convert("RGB"))


def test_interlaced_frames_differ_from_progressive_only_where_things_move(small_scene, gl, tmp_path):
    moving = open_source(str(small_scene(riders=True)), quiet=True, warm=True)  # a rider playing its clip
    still = open_source(str(small_scene(riders=False)), quiet=True, warm=True)  # nothing moves
    for b, moves in ((moving, True), (still, False)):
        prog = _first_frame(b, gl, tmp_path, "p", interlace=False)
        inter = _first_frame(b, gl, tmp_path, "i", interlace=True)
        p = ScenePreview(b, size=SIZE, ctx=gl)
        try:  # what moved between the two fields (t = 0 and half a frame later)
            cam = camera_at(b, "main")
            f0, f1 = p.render(cam, 0.0), p.render(cam, 0.5 / 30)
        finally:
            p.release()
        assert np.array_equal(prog, f0)
        differ = (inter != prog).any(axis=2)
        moved = (f0 != f1).any(axis=2)
        assert not differ[0::2].any()  # the even lines are the first field's
        assert not (differ & ~moved).any()  # and the odd lines differ only where the picture moved
        assert differ.any() == moves


def test_the_flicker_filter_reduces_the_scenes_flicker(small_scene, gl):
    b = open_source(str(small_scene(riders=True)), quiet=True, warm=True)
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        cams = [camera_at(b, "main")]
        fields = [p.render(cams[0], k / 60.0) for k in range(12)]
    finally:
        p.release()
    raw = np.stack([weave(fields[k], fields[k + 1]) for k in range(0, 12, 2)])
    filt = np.stack([weave(fields[k], fields[k + 1], filtered=True) for k in range(0, 12, 2)])
    assert flicker(raw) > 0
    assert flicker(filt) < flicker(raw)


def test_the_flicker_filter_needs_interlace(small_scene, gl):
    b = open_source(str(small_scene(riders=False)), quiet=True, warm=True)
    with pytest.raises(ConfigError, match="interlace"):
        render_frames(b, "main", 1, size=SIZE, ctx=gl, flicker_filter=True)


def test_the_cli_flags_reach_the_runtime(small_scene, tmp_path, capsys):
    from piste.cli import main

    scene = small_scene(riders=True)
    trace = tmp_path / "r.json"
    png = tmp_path / "r.png"
    assert main(["render", str(scene), "--frames", "2", "--size", "96", "64", "--out", str(png), "--quiet",
                 "--interlace", "--flicker-filter", "--trace", str(trace)]) == 0
    assert load_trace(trace)["metadata"]["frames"] == 4  # two fields a frame
    assert main(["render", str(scene), "--out", str(png), "--quiet", "--flicker-filter"]) != 0
    assert "--interlace" in capsys.readouterr().err


PACK_SCENE = """\
name = "pack"
[terrain]
source = "default"
[lightmap]
res = 2
shadows = false
[visibility]
enabled = false
[pack]
follow = "track"
start = 0.2
[auto_objects]
seed = 3
trees = 12
rocks = 3
"""


def test_the_pipelined_loop_traces_each_frame_with_the_next_ones_planning(tmp_path, gl):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle

    (tmp_path / "pack.toml").write_text(PACK_SCENE)
    b = load_bundle(build_scene(tmp_path / "pack.toml").path)
    path = tmp_path / "pipelined.json"
    p = ScenePreview(b, size=SIZE, ctx=gl, trace=path)
    try:
        assert p.follow
        n = sum(1 for _ in p.frames([k / 30 for k in range(4)]))
    finally:
        p.release()
    assert n == 4
    evs = [e for e in load_trace(path)["traceEvents"] if e["ph"] == "X" and e["tid"] == 1]
    frames = sorted((e for e in evs if e["name"] == "frame"), key=lambda e: e["ts"])
    assert [f["args"]["frame"] for f in frames] == [0, 1, 2, 3]
    plans = sorted((e for e in evs if e["name"] == "plan"), key=lambda e: e["ts"])
    assert [pl["args"]["t"] for pl in plans] == pytest.approx([k / 30 for k in range(4)])
    for f in frames:
        i = f["args"]["frame"]
        passes = [e for e in evs if e["cat"] == "pass" and e["args"]["frame"] == i]
        assert sorted(e["name"] for e in passes) == sorted(PASSES) and all(_inside(e, f) for e in passes)
        if i + 1 < len(plans):  # frame i + 1 is planned while frame i draws: inside frame i's span
            assert _inside(plans[i + 1], f)
