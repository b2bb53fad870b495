"""Fuzz-suite fixtures: seed files (shared test data, examples, a bundle built from a small
scene) and the end-of-session case counts."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # for `import fuzzlib`

import fuzzlib  # noqa: E402


def pytest_terminal_summary(terminalreporter):
    if not fuzzlib.COUNTS:
        return
    terminalreporter.section("piste fuzz cases")
    total = {"cases": 0, "loaded": 0, "refused": 0}
    for kind in sorted(fuzzlib.COUNTS):
        c = fuzzlib.COUNTS[kind]
        for k in total:
            total[k] += c[k]
        terminalreporter.write_line(f"{kind:<28} {c['cases']:6d} cases: {c['loaded']:6d} loaded, "
                                    f"{c['refused']:6d} refused with a PisteError naming the file")
    terminalreporter.write_line(f"{'total':<28} {total['cases']:6d} cases: {total['loaded']:6d} loaded, "
                                f"{total['refused']:6d} refused")


@pytest.fixture(scope="session")
def small_bundle(tmp_path_factory):
    """A bundle `piste build` made of a small scene (a 9 x 9 height field, one rider, one object)."""
    import numpy as np

    from piste.cli import main

    d = tmp_path_factory.mktemp("bundle")
    z = np.add.outer(np.linspace(0, 8, 13), np.linspace(0, 4, 13))
    np.savez(d / "h.npz", z=z, dx=np.array(10.0))
    (d / "s.toml").write_text(
        'name = "fuzz"\n[terrain]\nsource = "h.npz"\n[lightmap]\nres = 4\n[visibility]\ncell = 40.0\n'
        'eye_heights = [2.0]\n[[riders]]\nposition = [40.0, 40.0]\n[[objects]]\nmodel = "builtin:tree"\n'
        'position = [60.0, 60.0]\n[[lights]]\ntype = "directional"\ndirection = [0.3, 0.2, -1.0]\n'
        '[[cameras]]\nname = "c"\neye = [0.0, 0.0, 50.0]\ntarget = [60.0, 60.0, 0.0]\n')
    assert main(["build", str(d / "s.toml"), "--out", str(d / "s.piste"), "--quiet", "--no-cache"]) == 0
    return d / "s.piste"
