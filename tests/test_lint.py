"""ruff and mypy, configured in pyproject.toml ([tool.ruff], [tool.mypy]), find nothing in src/piste.

The rule sets start lenient (pyflakes, pycodestyle's errors and closures over loop variables; mypy
with the numpy-inference codes off) and pass today, so any NEW finding fails here, naming the file,
line and rule.  Both tools come with the ``dev`` extra (pinned in constraints.txt).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def _tool(name: str) -> list[str]:
    if importlib.util.find_spec(name) is None:
        pytest.skip(f"{name} is not installed (pip install -e '.[dev]')")
    return [sys.executable, "-m", name]


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)


def test_ruff_finds_nothing():
    r = _run([*_tool("ruff"), "check", "--no-cache", "--output-format", "concise", "src/piste"])
    assert r.returncode == 0, "ruff findings (fix them; the rules are in pyproject.toml [tool.ruff]):\n" + r.stdout + r.stderr


def test_mypy_finds_nothing():
    r = _run([*_tool("mypy")])  # files, strictness and cache from pyproject.toml [tool.mypy]
    assert r.returncode == 0, "mypy findings (fix them; the settings are in pyproject.toml [tool.mypy]):\n" + r.stdout + r.stderr


def test_the_checks_can_fail(tmp_path):
    """A planted unused import, loop-variable closure and wrong call are reported under this config."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        "import os\n\n\n"
        "def f(a: int) -> int:\n    return a\n\n\n"
        "def g() -> list:\n    out = []\n    for i in range(3):\n        out.append(lambda: i)\n    return out\n\n\n"
        "f(1, 2)\n"
    )
    r = _run([*_tool("ruff"), "check", "--no-cache", "--config", str(PYPROJECT), "--output-format", "concise", str(bad)])
    assert r.returncode == 1 and "F401" in r.stdout and "B023" in r.stdout, r.stdout + r.stderr
    r = _run([*_tool("mypy"), "--config-file", str(PYPROJECT), "--no-incremental", str(bad)])
    assert r.returncode == 1 and "[call-arg]" in r.stdout, r.stdout + r.stderr
