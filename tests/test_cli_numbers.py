"""Every number on the command line is checked by its argparse type (issue 24 item 3).

The numeric flags are found by walking ``piste``'s parser (every subcommand, nested ones such as
``piste mpf encode`` included), not listed by hand, and driven in-process with NaN, +-inf,
negatives, zero, huge and random values: each either parses to a finite value inside the type's
range or ends with exit status 2 and ONE line on stderr naming the flag (no traceback).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from piste.cli import build_parser, main
from piste.commands._numbers import NumberType

PARSER = build_parser()


def _positionals(p: argparse.ArgumentParser) -> list[str]:
    """Placeholder values for ``p``'s required positional arguments (a valid choice where it has choices)."""
    out = []
    for a in p._actions:
        if a.option_strings or isinstance(a, argparse._SubParsersAction) or a.nargs in ("?", "*"):
            continue
        n = a.nargs if isinstance(a.nargs, int) else 1
        out += [str(next(iter(a.choices))) if a.choices else "x"] * n
    return out


def _is_numeric(a: argparse.Action) -> bool:
    if not a.option_strings or a.nargs == 0:  # store_true and friends
        return False
    if isinstance(a.type, NumberType) or a.type in (int, float):
        return True
    d = a.default[0] if isinstance(a.default, (list, tuple)) and a.default else a.default
    if isinstance(d, (int, float)) and not isinstance(d, bool):
        return True
    return bool(a.choices) and all(isinstance(c, (int, float)) for c in a.choices)


def numeric_flags() -> list[tuple[tuple[str, ...], argparse.Action]]:
    """``(argv prefix: subcommand path and its positionals, action)`` for every numeric flag."""
    found = []

    def walk(p: argparse.ArgumentParser, path: list[str]) -> None:
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sub in a.choices.items():
                    walk(sub, [*path, name])
            elif _is_numeric(a):
                found.append((tuple(path + _positionals(p)), a))

    walk(PARSER, [])
    return found


FLAGS = numeric_flags()
IDS = [f"{prefix[0]}{'-' + prefix[1] if prefix[0] in ('mpf', 'ssx') else ''}:{a.option_strings[-1]}" for prefix, a in FLAGS]
HOSTILE = ["nan", "NaN", "inf", "-inf", "+inf", "infinity", "-1", "-0", "0", "0.0", "1e300", "-1e300", "1e-300",
           "-1e-300", "99999999999999999999", "1" + "0" * 400, "1e309", "0x10", "", " ", "1_000", "12abc", "1.5",
           "-10", "100000", "4294967296", "9e18"]


def test_the_walk_finds_every_subcommands_numbers():
    """The walk reaches nested parsers and finds the flags the issue names (so the drive below is not vacuous)."""
    names = {(prefix[0], a.option_strings[-1]) for prefix, a in FLAGS}
    for want in [("demo", "--seed"), ("demo", "--fov"), ("demo", "--height"), ("demo", "--size"),
                 ("render", "--speed"), ("render", "--budget"), ("view", "--watch-seconds"), ("bake", "--res"),
                 ("bake", "--chunk-size"), ("build", "--workers"), ("stats", "--near"), ("ssx", "--eye"),
                 ("mpf", "--ratios")]:
        assert want in names
    assert len(FLAGS) >= 35


@pytest.mark.parametrize(("prefix", "action"), FLAGS, ids=IDS)
def test_every_numeric_flag_has_a_checked_type(prefix, action):
    """No raw ``type=int`` / ``type=float``: each numeric flag's type is a range-checked NumberType, and
    its default (when a number) is inside that range."""
    assert isinstance(action.type, NumberType), f"{' '.join(prefix)} {action.option_strings}: type={action.type!r}"
    defaults = action.default if isinstance(action.default, (list, tuple)) else [action.default]
    for d in defaults:
        if d is not None:
            assert action.type(str(d)) == d


def _parse(argv: list[str]) -> tuple[argparse.Namespace | None, int | None, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            return PARSER.parse_args(argv), None, err.getvalue()
        except SystemExit as exc:
            return None, exc.code, err.getvalue()


def _check(prefix, action, value: str, joined: bool) -> None:
    n = action.nargs if isinstance(action.nargs, int) else 1
    opt = action.option_strings[-1]
    argv = [*prefix, f"{opt}={value}"] if joined and n == 1 else [*prefix, opt, *[value] * n]
    ns, code, err = _parse(argv)
    if ns is not None:
        got = getattr(ns, action.dest)
        values = got if isinstance(got, list) else [got]
        for v in values:
            assert isinstance(v, (int, float)) and math.isfinite(v), (argv, v)
            t = action.type
            assert t.lo is None or (v > t.lo if t.lo_open else v >= t.lo), (argv, v)
            assert t.hi is None or (v < t.hi if t.hi_open else v <= t.hi), (argv, v)
        assert err == ""
    else:
        assert code == 2, (argv, code, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1, (argv, err)
        assert "Traceback" not in err
        assert any(o in lines[0] for o in action.option_strings), (argv, err)


@pytest.mark.parametrize(("prefix", "action"), FLAGS, ids=IDS)
def test_hostile_values(prefix, action):
    for value in HOSTILE:
        for joined in (True, False):
            _check(prefix, action, value, joined)


@given(data=st.data())
@settings(max_examples=300, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
def test_random_values(data):
    prefix, action = data.draw(st.sampled_from(FLAGS))
    value = data.draw(st.one_of(st.floats().map(repr), st.integers().map(str),
                                st.floats(allow_nan=False, allow_infinity=False).map(lambda x: f"{x:g}"),
                                st.sampled_from(HOSTILE), st.text(max_size=8)))
    value = value.replace("\x00", "")
    _check(prefix, action, value, data.draw(st.booleans()))


@pytest.mark.parametrize("argv", [
    ["demo", "--seed", "-1"], ["render", "w.tiles", "--speed", "nan"], ["demo", "--height", "nan"],
    ["demo", "--fov", "-10"], ["demo", "--fov", "1e300"], ["demo", "--fov", "180"], ["bake", "--res", "0"],
    ["demo", "--size", "100000", "64"], ["render", "s.toml", "--budget=inf"], ["stats", "--far", "0"],
    ["ssx", "make", "d", "--rows", "1000000"], ["demo", "--frames", "10000000000"],
])
def test_the_issues_cases_exit_2_with_one_line(argv, capsys):
    """Through main(): exit status 2, one stderr line naming the flag, nothing run."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    flag = [a for a in argv if a.startswith("--")][-1].split("=")[0]
    prog = " ".join(argv[:2]) if argv[0] in ("ssx", "mpf") else argv[0]  # subcommands: `piste ssx make: error: ...`
    assert err.count("\n") == 1 and err.startswith(f"piste {prog}: error: argument {flag}: ")
    assert "expected" in err or "invalid choice" in err


def test_valid_values_still_parse():
    ns = PARSER.parse_args(["demo", "--seed", "7", "--fov", "75.5", "--height", "30", "--start", "0", "--end", "1"])
    assert (ns.seed, ns.fov, ns.height, ns.start, ns.end) == (7, 75.5, 30.0, 0.0, 1.0)
    ns = PARSER.parse_args(["stats", "--eye", "-1000.5", "2", "3.5", "--near", "0.5"])
    assert ns.eye == [-1000.5, 2.0, 3.5] and ns.near == 0.5
