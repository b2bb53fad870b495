"""The performance analyzer's tracer (piste.render.trace): the no-op default, spans, the written file."""

from __future__ import annotations

import json

import pytest

from piste.render.trace import NULL_TRACER, ChromeTracer, TraceError, load_trace, make_tracer


def test_the_default_tracer_records_nothing_and_shares_one_context():
    assert make_tracer(None) is NULL_TRACER and not NULL_TRACER.enabled
    a, b = NULL_TRACER.span("x"), NULL_TRACER.gpu_pass("y")
    assert a is b is NULL_TRACER.frame()  # one shared nullcontext: nothing made per span
    with NULL_TRACER.frame(), NULL_TRACER.gpu_pass("terrain"):
        pass
    assert NULL_TRACER.close() is None


def test_cpu_spans_nest_in_their_frame_and_empty_frames_are_dropped(tmp_path):
    tr = ChromeTracer(tmp_path / "t.json")
    for i in range(3):
        with tr.frame(i):
            with tr.frame():  # an inner frame (the renderer's) is part of the outer one
                with tr.span("plan"):
                    with tr.span("scene update"):
                        pass
                with tr.gpu_pass("terrain"):  # no GL context: a CPU span only
                    pass
    with tr.frame():  # nothing happened: no span
        pass
    data = load_trace(tr.close())
    evs = [e for e in data["traceEvents"] if e["ph"] == "X"]
    frames = [e for e in evs if e["name"] == "frame"]
    assert [f["args"]["frame"] for f in frames] == [0, 1, 2]
    for f in frames:
        kids = [e for e in evs if e["name"] != "frame" and e["args"]["frame"] == f["args"]["frame"]]
        assert sorted(e["name"] for e in kids) == ["plan", "scene update", "terrain"]
        for e in kids:
            assert f["ts"] <= e["ts"] and e["ts"] + e["dur"] <= f["ts"] + f["dur"] + 1e-3
    assert data["metadata"]["frames"] == 3 and data["metadata"]["gpu_timing"].startswith("none")


def test_gpu_passes_are_timed_with_queries_or_glfinish(gl, tmp_path):
    fbo = gl.simple_framebuffer((64, 64))  # (not bound: no later test is left with a released framebuffer)
    soft = "llvmpipe" in str(gl.info.get("GL_RENDERER", "")).lower()
    for mode, timing in (("query", "GL_TIME_ELAPSED"), ("finish", "glFinish"),
                         ("auto", "glFinish" if soft else "GL_TIME_ELAPSED")):
        tr = ChromeTracer(tmp_path / f"{mode}.json", ctx=gl, gpu=mode)
        for i in range(2):
            with tr.frame(i):
                with tr.gpu_pass("clear"):
                    fbo.clear(0.2, 0.3, 0.4, 1.0)
                gl.finish()
        assert set(tr.last) == {"clear"} and tr.last["clear"][1] >= 0.0
        data = load_trace(tr.close())
        assert data["metadata"]["gpu_timing"] == timing and data["metadata"]["gpu_timing_why"]
        gpu = [e for e in data["traceEvents"] if e["ph"] == "X" and e["tid"] == 2 and e["name"] == "clear"]
        assert len(gpu) == 2 and all(e["cat"] == "gpu" for e in gpu)
    fbo.release()


def test_bad_trace_paths_and_files_are_clear_errors(tmp_path):
    with pytest.raises(TraceError, match="json"):
        make_tracer(tmp_path / "trace.txt")
    with pytest.raises(TraceError, match="gpu timing"):
        ChromeTracer(tmp_path / "t.json", gpu="fast")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"traceEvents": [{"ph": "X", "name": "frame", "ts": 0, "dur": -1, "pid": 1, "tid": 1,
                                                "cat": "frame"}]}))
    with pytest.raises(TraceError, match=r"traceEvents\[0\]\.dur"):
        load_trace(bad)
    (tmp_path / "torn.json").write_text('{"traceEvents": [')
    with pytest.raises(TraceError, match="torn.json"):
        load_trace(tmp_path / "torn.json")
    tr = ChromeTracer(tmp_path / "file" / "t.json")
    (tmp_path / "file").write_text("a file where the folder should be")
    with pytest.raises(TraceError, match="cannot write"):
        tr.close()
