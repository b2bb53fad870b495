"""The benchmarks' contract (issue 15 item 8): every ``benchmarks/bench_*.py`` parses ``--help``
(without running) and offers ``--quick``; a peer that is missing or cannot run here is reported with
its reason (printed and recorded in the summary), never a crash."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import types
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(BENCH.glob("bench_*.py"))


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_benchmarks_found():
    assert len(SCRIPTS) >= 10


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_help_lists_quick(script):
    res = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("usage:")
    assert "--quick" in res.stdout


def test_frame_bench_offers_the_piste_render_runtime_section():
    """bench_frame measures examples/scenes/default.toml through ``piste render``'s runtime (issue 23
    item 2): alone with ``--render-only``, on a scene file that exists."""
    res = subprocess.run([sys.executable, str(BENCH / "bench_frame.py"), "--help"], capture_output=True, text=True,
                         timeout=60)
    assert "--render-only" in res.stdout
    assert _load("bench_frame").RENDER_SCENE.is_file()


def test_build_bench_offers_an_interleaved_baseline():
    """bench_build times another copy of piste's sources in the same rounds (``--baseline-src``, issue
    23 item 4: a cold-start change's before/after, interleaved)."""
    res = subprocess.run([sys.executable, str(BENCH / "bench_build.py"), "--help"], capture_output=True, text=True,
                         timeout=60)
    assert "--baseline-src" in res.stdout
    assert "baseline_src" in _load("bench_build").fresh_first_frame.__code__.co_varnames


def test_embree_peer_missing_is_reported(monkeypatch, tmp_path, capsys):
    bake = _load("bench_bake")
    out = tmp_path / "rows.jsonl"
    monkeypatch.setenv("PISTE_BENCH_OUT", str(out))
    monkeypatch.setitem(sys.modules, "embreex", None)  # import embreex -> ImportError
    bake.embree_peer(None, None, 8, (8,), 1)
    assert "Embree peer skipped: embreex is not installed" in capsys.readouterr().out
    row = json.loads(out.read_text().splitlines()[0])
    assert row["bench"] == "bake" and row["peer"].startswith("skipped")


@pytest.mark.gl
def test_vispy_peer_without_headless_gl_is_reported(gl_context, monkeypatch, tmp_path, capsys):
    draw = _load("bench_draw")
    peer = sys.modules.get("_vispy_peer") or _load("_vispy_peer")
    monkeypatch.setitem(sys.modules, "_vispy_peer", peer)

    def no_canvas(size):
        raise RuntimeError('Could not import backend "EGL":\nCould not initialize')

    monkeypatch.setattr(peer, "make_canvas", no_canvas)
    out = tmp_path / "rows.jsonl"
    monkeypatch.setenv("PISTE_BENCH_OUT", str(out))
    assert draw.main(["--quick"]) == 0
    text = capsys.readouterr().out
    assert 'vispy peer not run: RuntimeError: Could not import backend "EGL": Could not initialize' in text
    row = json.loads(out.read_text().splitlines()[0])
    assert row["bench"] == "draw" and row["peer"].startswith("not run: RuntimeError")


def test_interleaved_times_only_the_call_and_rotates_the_order(monkeypatch):
    """(setup, call) pairs: the set-up (e.g. handing a peer its input through its API) is outside the
    timed region; round r starts at contender r mod k.  A fake clock: setup advances it 100, a call 1."""
    timing = _load("_timing")
    now = [0.0]
    order = []
    monkeypatch.setattr(timing, "_clock", lambda: now[0])

    def tick(dt, name=None):
        def f():
            now[0] += dt
            if name:
                order.append(name)
        return f

    t = timing.interleaved({"a": (tick(100.0), tick(1.0, "a")), "b": tick(2.0, "b"), "c": tick(3.0, "c")},
                           rounds=3, warmup=0, inner=2)
    assert t["a"].tolist() == [1.0, 1.0, 1.0] and t["b"].tolist() == [2.0] * 3 and t["c"].tolist() == [3.0] * 3
    assert order == ["a", "a", "b", "b", "c", "c", "b", "b", "c", "c", "a", "a", "c", "c", "a", "a", "b", "b"]


def test_summary_runs_the_window_bench_under_xvfb_or_says_it_cannot(monkeypatch):
    summary = _load("summary")
    view = BENCH / "bench_view.py"
    monkeypatch.setattr(summary.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(summary.shutil, "which", lambda name: "/usr/bin/xvfb-run" if name == "xvfb-run" else None)
    cmd, note = summary._command(view, full=False)
    assert cmd[0] == "/usr/bin/xvfb-run" and cmd[-2:] == [str(view), "--quick"] and "xvfb-run" in note
    monkeypatch.setattr(summary.shutil, "which", lambda name: None)
    cmd, note = summary._command(view, full=True)
    assert cmd == [sys.executable, str(view)] and "skipped" in note
    monkeypatch.setenv("DISPLAY", ":99")
    assert summary._command(view, full=False)[0] == [sys.executable, str(view), "--quick"]
    assert summary._command(BENCH / "bench_terrain.py", full=False)[0][0] == sys.executable


def test_window_bench_without_a_display_is_skipped_and_recorded(monkeypatch, tmp_path, capsys):
    view = _load("bench_view")
    monkeypatch.setattr(view.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "rows.jsonl"
    monkeypatch.setenv("PISTE_BENCH_OUT", str(out))
    assert view.main(["--quick"]) == 0
    assert "bench_view skipped: no display" in capsys.readouterr().out
    row = json.loads(out.read_text().splitlines()[0])
    assert row["bench"] == "view" and row["peer"].startswith("skipped: no display")


def test_summary_writes_the_markdown_table(tmp_path):
    summary = _load("summary")
    rows = [{"bench": "skinning", "what": "six riders | palette", "goal": ">= 4x", "piste": "30 us", "peer": "210 us",
             "ratio": "7.0x", "met": True},
            {"bench": "view", "what": "window", "goal": "<= 1.10x", "piste": "", "peer": "skipped: no display",
             "ratio": "", "met": None},
            {"bench": "terrain", "what": "CPU side", "goal": "<= 2 ms", "piste": "3 ms", "peer": "", "ratio": "",
             "met": False}]
    args = types.SimpleNamespace(full=False)
    text = summary.markdown(rows, args, {"bench_skinning": 3.0}, [], "2026-01-01 00:00 UTC", "test machine")
    lines = text.splitlines()
    table = [ln for ln in lines if ln.startswith("|")]
    assert len(table) == 2 + len(rows)
    assert table[2].count("|") == len(summary.HEAD) + 1  # a '|' inside a cell does not split it
    assert "| yes |" in table[2] and table[3].endswith("|  |") and "**no**" in table[4]
    assert "summary.py --quick" in text and "test machine" in text
