"""Optional: the user's own extracted SSX Tricky levels (never in the repo).

Set ``PISTE_SSX_TRICKY_DIR`` to a folder holding extracted ``<NAME>.pbd`` files (with ``<NAME>.ssh``
and ``<NAME>_L.ssh`` beside them, as the game's BIG archives hold them).  Skipped otherwise.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.ssx import lightmap_pages, parse_pbd, read_pbd, read_ssh
from piste.pipeline.ssx_level import level_files

ROOT = os.environ.get("PISTE_SSX_TRICKY_DIR")
pytestmark = pytest.mark.skipif(not ROOT, reason="PISTE_SSX_TRICKY_DIR is not set (point it at your own extracted "
                                                  "SSX Tricky level files to run this test)")


def _levels():
    files = sorted(p for p in Path(ROOT).rglob("*") if p.suffix.lower() == ".pbd" and "_sky" not in p.stem.lower())
    if not files:
        pytest.fail(f"PISTE_SSX_TRICKY_DIR={ROOT}: no .pbd files found")
    return files


def test_real_levels_round_trip_and_weld():
    for path in _levels():
        pbd = read_pbd(path)
        assert pbd.to_bytes() == pbd.raw, f"{path.name}: not written back byte for byte"
        assert pbd.n_patches > 0 and pbd.platform == 1
        # an edited patch re-encodes within float32 of the edit, the rest stays bit-identical
        q = parse_pbd(pbd.raw, path)
        q.control_points[0, 1, 1, 2] += 10.0
        r = parse_pbd(q.to_bytes(), path)
        np.testing.assert_allclose(r.control_points[0], q.control_points[0], atol=0.5)
        np.testing.assert_array_equal(r.records["power"][1:], pbd.records["power"][1:])
        net = pbd.to_net()
        assert len(net.shared_edges) > 0.5 * len(net), f"{path.name}: few seams welded"


def test_real_banks_read_or_refuse_clearly():
    for path in _levels():
        ssh, lssh = level_files(path)
        for bank in (ssh, lssh):
            if bank is None:
                continue
            try:
                b = read_ssh(bank)
            except FormatError as exc:  # allowed only with the "not supported yet" message
                assert "not supported yet" in str(exc), str(exc)
                continue
            assert len(b) > 0
            if bank is lssh:
                pages = lightmap_pages(b, lssh)
                assert pages.shape[1:] == (128, 128, 4)
                pbd = read_pbd(path)
                assert int(pbd.lightmap_page.max()) < len(pages)
