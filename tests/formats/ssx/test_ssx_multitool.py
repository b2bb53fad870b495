"""Multitool project (Patches.json + Textures/ + Lightmaps/) write and read back."""

from __future__ import annotations

import json

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.ssx import make_level
from piste.formats.ssx.multitool import read_project, write_project
from piste.formats.ssx.ssh import lightmap_pages


@pytest.fixture(scope="module")
def level():
    return make_level(rows=2, cols=2, seed=4, trick_every=3)


def test_round_trip(level, tmp_path):
    write_project(tmp_path, level.pbd, level.textures, level.lightmaps)
    doc = json.loads((tmp_path / "Patches.json").read_text())
    p0 = doc["Patches"][0]
    assert set(p0) == {"PatchName", "LightMapPoint", "UVPoints", "Points", "SurfaceType", "TrickOnlyPatch",
                       "TexturePath", "LightmapID"}
    assert len(p0["Points"]) == 16 and len(p0["UVPoints"]) == 4 and p0["TexturePath"] == "0000.png"
    assert sorted(f.name for f in (tmp_path / "Textures").iterdir()) == ["0000.png", "0001.png", "0002.png"]
    proj = read_project(tmp_path)
    np.testing.assert_array_equal(proj.control_points, level.pbd.control_points)
    np.testing.assert_array_equal(proj.trick_only, level.pbd.trick_only)
    np.testing.assert_array_equal(proj.texture_index, level.pbd.texture_index)
    pbd, tex, lms = proj.to_level()
    np.testing.assert_allclose(pbd.control_points, level.pbd.control_points, atol=0.05)
    np.testing.assert_array_equal(pbd.uv, level.pbd.uv)
    np.testing.assert_array_equal(pbd.lightmap_rect, level.pbd.lightmap_rect)
    for a, b in zip(tex.images, level.textures.images):
        np.testing.assert_array_equal(a.stored_rgba(), b.stored_rgba())
    np.testing.assert_array_equal(lightmap_pages(lms), lightmap_pages(level.lightmaps))


def test_bad_projects(tmp_path, level):
    with pytest.raises(FormatError, match="no such file"):
        read_project(tmp_path)
    write_project(tmp_path, level.pbd)
    doc = json.loads((tmp_path / "Patches.json").read_text())
    doc["Patches"][1]["TexturePath"] = "../../etc/passwd.png"
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="patch 1: TexturePath"):
        read_project(tmp_path)
    doc["Patches"][1]["TexturePath"] = "0001.png"
    del doc["Patches"][2]["Points"]
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="patch 2: missing key") as e:
        read_project(tmp_path)
    assert e.value.field == "Points"
