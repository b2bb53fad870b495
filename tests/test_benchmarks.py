"""The benchmarks' contract (issue 15 item 8): every ``benchmarks/bench_*.py`` parses ``--help``
(without running) and offers ``--quick``; a peer that is missing or cannot run here is reported with
its reason (printed and recorded in the summary), never a crash."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
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
