"""The README is a five-minute read and every command in it works exactly as written.

Each line of its ``sh`` code blocks is run, in order, by bash in the checkout's root (``../shared``,
the test data, beside it, as on a fresh clone after ``make demo``), and must exit 0.  Two lines are
not run by this test: ``make test`` (it is the command that runs this test), and the glTF
validator without its tools (``make test-tools``), which skips like the other validator tests
(fails instead with ``PISTE_REQUIRE_TOOLS=1``).  Commands that draw need an OpenGL context (skipped
without one, failed with ``PISTE_REQUIRE_GL=1``, like every GL test).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
VALIDATOR = ROOT / ".tools" / "node_modules" / "gltf-validator"
MAX_LINES = 200


def readme_commands(text: str) -> list[str]:
    """The command lines of the ``sh`` blocks (a trailing ``  # comment`` dropped), in order."""
    out = []
    for block in re.findall(r"^```sh\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.splitlines():
            line = re.sub(r"\s+#\s.*$", "", line).strip()
            if line and not line.startswith("#"):
                out.append(line)
    return out


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))
DRAWS = ("make demo", "piste demo", "piste render", "piste view")


def test_the_readme_is_short_and_its_links_and_picture_exist():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= MAX_LINES, f"README.md has {len(text.splitlines())} lines (at most {MAX_LINES})"
    links = re.findall(r"\]\(([^)#\s]+)\)", text)
    assert any(link.endswith((".png", ".jpg")) for link in links), "the README shows a picture"
    missing = [link for link in links if "://" not in link and not (ROOT / link).exists()]
    assert not missing, f"README.md links to files that do not exist: {missing}"
    assert "make demo" in COMMANDS and "make test" in COMMANDS and len(COMMANDS) >= 8


def test_readme_commands_parse():
    text = "intro\n```sh\nmake demo   # set up\n# a comment\n.venv/bin/piste stats\n```\n```python\nx = 1\n```\n"
    assert readme_commands(text) == ["make demo", ".venv/bin/piste stats"]


@pytest.mark.slow
@pytest.mark.parametrize("command", COMMANDS)
def test_readme_command_runs_as_written(command, request):
    if command == "make test":
        pytest.skip("`make test` is what runs this test")
    if command.startswith("node tools/gltf_validate.mjs") and (shutil.which("node") is None or not VALIDATOR.is_dir()):
        if os.environ.get("PISTE_REQUIRE_TOOLS") == "1":
            pytest.fail("PISTE_REQUIRE_TOOLS=1 but the glTF validator is not installed (make test-tools)")
        pytest.skip("the glTF validator is not installed (make test-tools)")
    if any(d in command for d in DRAWS):
        request.getfixturevalue("gl_context")
    (ROOT / "out").mkdir(exist_ok=True)  # what `make demo`, the README's first command, leaves behind
    r = subprocess.run(["bash", "-c", command], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"{command}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
