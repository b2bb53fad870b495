"""The resident terrain's shape templates shipped with the package equal what the code computes
(regenerate with ``piste.terrain.resident.write_templates()`` after changing the shapes)."""

from __future__ import annotations

import numpy as np
from nets import grid_net

from piste.terrain import resident as R


def test_shipped_templates_equal_the_computed_ones():
    shipped = R.shipped_templates(R.LEVELS)
    assert shipped is not None, f"{R.TEMPLATES_FILE} is missing or unreadable"
    computed = R.shape_templates(R.LEVELS)
    assert set(shipped) == set(computed)
    for k, v in computed.items():
        assert shipped[k].dtype == v.dtype and np.array_equal(shipped[k], v), k


def test_other_levels_and_bad_files_are_computed(tmp_path, monkeypatch):
    assert R.shipped_templates((3, 5, 7)) is None
    net = grid_net(2, 2)
    ref = R.ResidentTerrain(net)
    for bad in (b"", b"not an npz", None):
        p = tmp_path / "t.npz"
        if bad is None:  # an npz with a wrong count
            np.savez(p, levels=np.array(R.LEVELS), tmpl=np.zeros(3, np.uint32), tmpl_start=np.zeros(2, np.int64),
                     tmpl_count=np.zeros(2, np.int64), shape_kind=np.zeros(2, np.int8), shape_verts=np.zeros(2, np.int64))
        else:
            p.write_bytes(bad)
        monkeypatch.setattr(R, "TEMPLATES_FILE", p)
        assert R.shipped_templates(R.LEVELS) is None
        r = R.ResidentTerrain(net)
        assert np.array_equal(r.tmpl, ref.tmpl) and np.array_equal(r.tmpl_start, ref.tmpl_start)
    other = R.ResidentTerrain(net, levels=(3, 5, 7))
    assert np.array_equal(other.tmpl, R.shape_templates((3, 5, 7))["tmpl"])
