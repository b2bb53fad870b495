"""Filesystem errors reach the user as one line naming the path (issue 10 items 3, 6): an
unwritable or full output or cache in `build`, `bake`, `render`; checked before long work."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest

from piste.cli import main



@pytest.fixture
def blocker(tmp_path):
    """A regular file: any path through it cannot be created, even by root."""
    f = tmp_path / "file"
    f.write_text("x")
    return f


def _one_line_error(capsys, command, fragment):
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"piste {command}: error: "), err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert fragment in err, err
    return err


def test_build_unwritable_output(tmp_path, blocker, capsys):
    (tmp_path / "s.toml").write_text('[lightmap]\nres = 4\n[visibility]\nenabled = false\n')
    assert main(["build", str(tmp_path / "s.toml"), "--out", str(blocker / "sub" / "s.piste"), "--quiet"]) == 1
    _one_line_error(capsys, "build", str(blocker / "sub"))


def test_build_unwritable_cache(tmp_path, blocker, capsys):
    (tmp_path / "s.toml").write_text('[lightmap]\nres = 4\n[visibility]\nenabled = false\n')
    assert main(["build", str(tmp_path / "s.toml"), "--cache", str(blocker / "cache"), "--quiet"]) == 1
    _one_line_error(capsys, "build", str(blocker / "cache"))


def test_bake_unwritable_output(blocker, capsys):
    assert main(["bake", "--out", str(blocker / "lm"), "--quiet", "--jobs", "1"]) == 1
    _one_line_error(capsys, "bake", str(blocker / "lm"))


def test_render_unwritable_output(tmp_path, blocker, capsys, gl_context):
    """A bundle built here (no skip: the test makes its own input) rendered into a folder that cannot exist."""
    (tmp_path / "s.toml").write_text('[lightmap]\nres = 4\n[visibility]\nenabled = false\n')
    bundle = tmp_path / "s.piste"
    assert main(["build", str(tmp_path / "s.toml"), "--out", str(bundle), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["render", str(bundle), "--out", str(blocker / "x" / "r.png"), "--quiet", "--size", "32", "24"]) == 1
    _one_line_error(capsys, "render", str(blocker / "x"))


def test_any_oserror_at_the_command_boundary_is_one_line(monkeypatch, capsys):
    import piste.commands.stats as stats

    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device", "/some/out/file.bin")

    monkeypatch.setattr(stats, "run", full)
    assert main(["stats"]) == 1
    _one_line_error(capsys, "stats", "/some/out/file.bin: no space left on the device (disk full)")
