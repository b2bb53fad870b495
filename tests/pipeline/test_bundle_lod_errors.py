"""The build's ``lod_errors`` step: the terrain LOD's per-patch error table (flat and coarsest
levels) stored in the bundle, kept on the loaded net so the first frame does not compute it (the
same per-edge errors, the same picture); bundles without it still load (computed as before); a bad
table gives a FormatError naming the member."""

from __future__ import annotations

import numpy as np
import pytest

import piste.terrain.lod as lod
from piste.errors import FormatError, ValidationError
from piste.formats.bundle import write_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import LOD_ERRORS_FORMAT, LOD_ERRORS_MEMBER, load_bundle, lod_error_members
from piste.terrain.lod import FLAT_LEVEL, LEVELS, STORED_ERROR_LEVELS, flat_bounds, keep_patch_errors, level_errors
from piste.terrain.net import PatchNet
from tests.pipeline.conftest import mini_bundle_parts


def _net() -> PatchNet:
    g = np.zeros((10, 10, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(10.0) * 4.0, np.arange(10.0) * 4.0)
    g[..., 2] = 0.3 * g[..., 0] + np.sin(g[..., 1]) + 0.5 * np.cos(g[..., 0] / 3.0)
    return PatchNet.from_control_grid(g)


def _bundle(tmp_path, table: bool = True, name: str = "b.piste", edit=None):
    net = _net()
    man, arrays = mini_bundle_parts(net)
    if table:
        la, meta = lod_error_members(net)
        arrays.update(la)
        man["lod_errors"] = meta
    if edit is not None:
        edit(man, arrays)
    return write_bundle(tmp_path / name, man, arrays)


def _computed(net: PatchNet):
    """The per-edge errors computed from the net alone (no stored table)."""
    fresh = PatchNet(np.asarray(net.control_points))
    return flat_bounds(fresh), level_errors(fresh, LEVELS[0])


def test_the_load_keeps_the_table_and_the_frame_does_not_compute_it(tmp_path, monkeypatch):
    path = _bundle(tmp_path)
    b = load_bundle(path, warm=True)
    assert b.manifest["lod_errors"] == {"levels": [FLAT_LEVEL, LEVELS[0]], "format": LOD_ERRORS_FORMAT}
    assert b.arrays[LOD_ERRORS_MEMBER].shape == (len(b.net), 2) and b.arrays[LOD_ERRORS_MEMBER].dtype == np.float64
    (ferr, flo, fhi), cerr = _computed(b.net)
    assert ferr.max() > 0 and cerr.max() > 0  # a curved net: the errors are not all zero

    def no(*_a, **_k):
        raise AssertionError("the per-patch errors were computed, not taken from the bundle")

    monkeypatch.setattr(lod, "_patch_errors", no)
    got_f, got_lo, got_hi = flat_bounds(b.net)
    assert np.array_equal(got_f, ferr) and np.array_equal(got_lo, flo) and np.array_equal(got_hi, fhi)
    assert np.array_equal(level_errors(b.net, LEVELS[0]), cerr)


def test_a_bundle_without_the_table_computes_the_same_errors(tmp_path, monkeypatch):
    b = load_bundle(_bundle(tmp_path, table=False))
    assert LOD_ERRORS_MEMBER not in b.arrays and "_stored_patch_errors" not in b.net.__dict__
    (ferr, _, _), cerr = _computed(b.net)
    assert np.array_equal(flat_bounds(b.net)[0], ferr) and np.array_equal(level_errors(b.net, LEVELS[0]), cerr)


def test_another_format_or_levels_are_not_used(tmp_path):
    for meta in ({"levels": [FLAT_LEVEL, LEVELS[0]], "format": LOD_ERRORS_FORMAT + 1},
                 {"levels": [FLAT_LEVEL, LEVELS[1]], "format": LOD_ERRORS_FORMAT}):
        path = _bundle(tmp_path, edit=lambda man, arrays, m=meta: man.update(lod_errors=m))
        assert "_stored_patch_errors" not in load_bundle(path).net.__dict__


@pytest.mark.parametrize("bad", ["shape", "dtype", "nan", "negative"])
def test_a_bad_table_names_the_member(tmp_path, bad):
    def edit(man, arrays):
        t = np.array(arrays[LOD_ERRORS_MEMBER])
        if bad == "shape":
            t = t[:-1]
        elif bad == "dtype":
            t = t.astype(np.float32)
        elif bad == "nan":
            t[3, 1] = np.nan
        else:
            t[2, 0] = -1.0
        arrays[LOD_ERRORS_MEMBER] = t

    with pytest.raises(FormatError) as e:
        load_bundle(_bundle(tmp_path, edit=edit))
    assert e.value.field == LOD_ERRORS_MEMBER + ".npy" and "LOD error table" in str(e.value)


def test_keep_patch_errors_checks_the_table():
    net = _net()
    with pytest.raises(ValidationError, match="float64"):
        keep_patch_errors(net, np.zeros((len(net), 3)), STORED_ERROR_LEVELS)
    with pytest.raises(ValidationError, match="finite"):
        keep_patch_errors(net, np.full((len(net), 2), np.inf), STORED_ERROR_LEVELS)


def test_the_build_step_stores_the_table_and_caches_it(small_scene):
    r = build_scene(small_scene(riders=False))
    assert "lod_errors" in r.steps and not r.steps["lod_errors"]["cached"]
    b = load_bundle(r.path)
    assert "_stored_patch_errors" in b.net.__dict__
    (ferr, _, _), cerr = _computed(b.net)
    stored = b.arrays[LOD_ERRORS_MEMBER]
    assert np.array_equal(stored[:, 0], lod._patch_errors(b.net, FLAT_LEVEL))
    assert np.array_equal(flat_bounds(b.net)[0], ferr) and np.array_equal(level_errors(b.net, LEVELS[0]), cerr)
    again = build_scene(r.path.with_suffix(".toml"))
    assert again.steps["lod_errors"]["cached"] and again.path.read_bytes() == r.path.read_bytes()


def test_the_table_draws_the_same_picture(tmp_path, gl):
    from piste.pipeline.preview import ScenePreview, camera_at

    images = []
    for table in (True, False):
        b = load_bundle(_bundle(tmp_path, table=table, name=f"b{int(table)}.piste"), warm=True)
        assert ("_stored_patch_errors" in b.net.__dict__) == table
        p = ScenePreview(b, size=(96, 64), ctx=gl)
        try:
            images.append(p.render(camera_at(b, "c")))
        finally:
            p.release()
    assert images[0].std() > 0 and np.array_equal(images[0], images[1])
