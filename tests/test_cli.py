"""The ``piste`` command line's conventions: ``--version``, exit status 1 for a runtime error and 2
for a usage error, ``-v``/``-q`` setting the level of the ``piste`` logger."""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

import piste
from piste.cli import build_parser, log_level, main


def test_version_prints_the_one_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"piste {piste.__version__}"


def test_a_runtime_error_exits_1_with_one_line(tmp_path, capsys):
    assert main(["stats", str(tmp_path / "missing.npz")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("piste stats: error: ") and "missing.npz" in err[0]


def test_a_usage_error_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["stats", "--no-such-flag"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        main(["no-such-command"])
    assert exc.value.code == 2


def test_a_real_process_exits_1_on_a_runtime_error(tmp_path):
    r = subprocess.run([sys.executable, "-m", "piste.cli", "stats", str(tmp_path / "missing.npz")],
                       capture_output=True, text=True)
    assert r.returncode == 1, r.stderr


@pytest.mark.parametrize("flags, level", [
    ([], logging.INFO), (["-v"], logging.DEBUG), (["-vv"], logging.DEBUG),
    (["-q"], logging.WARNING), (["-qq"], logging.ERROR), (["-qqq"], logging.ERROR),
])
def test_verbose_and_quiet_set_the_piste_loggers_level(flags, level):
    args = build_parser().parse_args([*flags, "stats"])
    assert log_level(args.verbose, args.quiet_log) == level


def test_library_messages_reach_stderr_through_the_logger_and_quiet_silences_them(monkeypatch, capsys):
    """A library message (logged, not printed) is on stderr as ``piste: ...`` by default, gone with
    ``-q``; the handler is removed when ``main`` returns (a second call does not print twice)."""
    import piste.commands.stats as stats

    def run(args):
        logging.getLogger("piste.terrain").info("fitting 12 patches")
        logging.getLogger("piste.terrain").debug("a detail")
        return 0

    monkeypatch.setattr(stats, "run", run)
    assert main(["stats"]) == 0
    assert capsys.readouterr().err.splitlines() == ["piste: fitting 12 patches"]
    assert main(["-v", "stats"]) == 0
    assert capsys.readouterr().err.splitlines() == ["piste: fitting 12 patches", "piste: a detail"]
    assert main(["-q", "stats"]) == 0
    assert capsys.readouterr().err == ""
    assert logging.getLogger("piste").level == logging.NOTSET


@pytest.mark.parametrize("command", ["stats", "bake"])
def test_one_load_net_for_every_command(tmp_path, capsys, command):
    """``piste stats`` and ``piste bake`` open a net through the one pipeline.open_scene.load_net:
    the same one-line error for a file that is not a .bpt or .npz net."""
    bad = tmp_path / "net.obj"
    bad.write_text("v 0 0 0\n")
    assert main([command, str(bad)] + (["--out", str(tmp_path / "lm")] if command == "bake" else [])) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"piste {command}: error: {bad}: expected a .bpt or .npz patch net"]
