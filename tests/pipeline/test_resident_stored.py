"""The terrain's resident vertex blocks stored in the bundle (format 2): written uncompressed by the
build, kept on the net by the load (no background build, the first frame does not wait), the same
bits and the same picture as blocks built at run time; old (format 1) bundles still load; bad
blocks or an unknown format give a FormatError naming the member / the rebuild command."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bundle import BUNDLE_FORMAT, RESIDENT_MEMBER, read_bundle, write_bundle
from piste.pipeline import load_bundle
from piste.pipeline.bundle_objects import STORED_BLOCKS_BUDGET, resident_members
from piste.terrain.net import PatchNet
from piste.terrain.resident import RESIDENT_FORMAT, ResidentTerrain, resident_terrain
from tests.pipeline.conftest import mini_bundle_parts


def _net():
    g = np.zeros((10, 10, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(10.0) * 4.0, np.arange(10.0) * 4.0)
    g[..., 2] = 0.3 * g[..., 0] + np.sin(g[..., 1])
    return PatchNet.from_control_grid(g)


def _bundle(tmp_path, blocks=True, name="b.piste", edit=None):
    net = _net()
    man, arrays = mini_bundle_parts(net)
    if blocks:
        ra, meta = resident_members(net)
        arrays.update(ra)
        man["terrain"]["resident"] = meta
    if edit is not None:
        edit(man, arrays)
    return write_bundle(tmp_path / name, man, arrays), net


def test_the_build_stores_the_blocks_uncompressed_and_the_load_keeps_them(tmp_path):
    path, net = _bundle(tmp_path)
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(RESIDENT_MEMBER + ".npy")
        assert info.compress_type == zipfile.ZIP_STORED
        assert json.loads(zf.read("manifest.json"))["format"] == BUNDLE_FORMAT == "piste.bundle/2"
    b = load_bundle(path, warm=True)
    assert not b.net.__dict__.get("_resident_pending")  # nothing built in the background
    r = resident_terrain(b.net, wait=False)  # there at once
    assert r is not None and r.vertices is b.arrays[RESIDENT_MEMBER]
    built = ResidentTerrain(_net()).vertices
    assert r.vertices.dtype == np.float32 and np.array_equal(r.vertices, built)
    assert not r.vertices.flags.writeable  # a view of the member's bytes (not copied)
    # the manifest entry the load checks: levels and block format
    assert b.manifest["terrain"]["resident"] == {"levels": [4, 6, 8], "format": RESIDENT_FORMAT}


def test_stored_blocks_draw_the_same_picture_as_built_ones(tmp_path, gl):
    from piste.pipeline.preview import ScenePreview, camera_at

    images = []
    for blocks in (True, False):
        path, _ = _bundle(tmp_path, blocks=blocks, name=f"b{int(blocks)}.piste")
        b = load_bundle(path, warm=True)
        assert bool(b.net.__dict__.get("_resident")) == blocks
        p = ScenePreview(b, size=(96, 64), ctx=gl)
        try:
            images.append(p.render(camera_at(b, "c")))
            assert p.terrain.mesh.resident.vertices.shape == (len(b.net) * 116, 11)
        finally:
            p.release()
    assert images[0].std() > 0 and np.array_equal(images[0], images[1])


def test_a_format_1_bundle_without_blocks_still_loads_and_builds_them(tmp_path):
    path, _ = _bundle(tmp_path, blocks=False)
    # rewrite its manifest's format as an older piste wrote it
    raw = tmp_path / "old.piste"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(raw, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "manifest.json":
                m = json.loads(data)
                m["format"] = "piste.bundle/1"
                data = json.dumps(m).encode()
            dst.writestr(item, data)
    b = load_bundle(raw, warm=True)
    assert b.manifest["format"] == "piste.bundle/1" and RESIDENT_MEMBER not in b.arrays
    r = resident_terrain(b.net, wait=True)  # built at run time (started in the background by warm=True)
    assert np.array_equal(r.vertices, ResidentTerrain(_net()).vertices)


def test_an_unknown_format_names_the_rebuild_command(tmp_path):
    path, _ = _bundle(tmp_path, blocks=False)
    raw = tmp_path / "future.piste"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(raw, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "manifest.json":
                data = json.dumps(dict(json.loads(data), format="piste.bundle/9")).encode()
            dst.writestr(item, data)
    with pytest.raises(FormatError) as e:
        read_bundle(raw)
    assert e.value.field == "format" and "piste build SCENE" in str(e.value) and "piste.bundle/9" in str(e.value)


@pytest.mark.parametrize("bad", ["shape", "slots", "nan"])
def test_bad_stored_blocks_name_the_member(tmp_path, bad):
    def edit(man, arrays):
        v = np.array(arrays[RESIDENT_MEMBER])
        if bad == "shape":
            v = v[:-1]
        elif bad == "slots":
            v[5, 10] = 1e6  # a morph slot past the net's edges and patches
        else:
            v[7, 10] = np.nan
        arrays[RESIDENT_MEMBER] = v

    path, _ = _bundle(tmp_path, edit=edit)
    with pytest.raises(FormatError) as e:
        load_bundle(path, warm=True)
    assert e.value.field == RESIDENT_MEMBER + ".npy" and "resident vertex blocks" in str(e.value)


def test_other_levels_or_block_format_are_not_used(tmp_path):
    def edit(man, arrays):
        man["terrain"]["resident"] = {"levels": [4, 6, 8], "format": RESIDENT_FORMAT + 1}

    path, _ = _bundle(tmp_path, edit=edit)
    b = load_bundle(path)
    assert not b.net.__dict__.get("_resident")  # left alone: built at run time from the net


def test_big_nets_store_no_blocks(monkeypatch):
    import piste.pipeline.bundle_objects as bo

    net = _net()
    assert resident_members(net)[1] is not None
    monkeypatch.setattr(bo, "STORED_BLOCKS_BUDGET", len(net) * 116 * 44 - 1)
    assert bo.resident_members(net) == ({}, None)
    assert STORED_BLOCKS_BUDGET >= 2560 * 116 * 44  # the default course's blocks are stored


def test_a_damaged_stored_member_names_it(tmp_path):
    """The blocks are stored uncompressed and read as a view of their bytes: a flipped byte in them
    (zip CRC) or a wrong SHA-256 still raises a FormatError naming the member."""
    path, _ = _bundle(tmp_path)
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(RESIDENT_MEMBER + ".npy")
        offset = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + 1000
    raw = bytearray(path.read_bytes())
    raw[offset] ^= 0xFF
    flipped = tmp_path / "flipped.piste"
    flipped.write_bytes(bytes(raw))
    with pytest.raises(FormatError) as e:
        load_bundle(flipped, warm=True)
    assert e.value.field == RESIDENT_MEMBER + ".npy" and "corrupt member" in str(e.value)

    wrong = tmp_path / "wrong_sha.piste"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(wrong, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "manifest.json":
                m = json.loads(data)
                m["members"][RESIDENT_MEMBER]["sha256"] = "0" * 64
                data = json.dumps(m).encode()
            dst.writestr(item, data)
    with pytest.raises(FormatError) as e:
        read_bundle(wrong)
    assert e.value.field == RESIDENT_MEMBER + ".npy" and "checksum mismatch" in str(e.value)
    assert read_bundle(wrong, verify=False).arrays[RESIDENT_MEMBER].shape == (len(_net()) * 116, 11)


def test_a_corrupt_block_member_is_named_as_corrupt_not_as_bad_blocks(tmp_path, monkeypatch):
    """load_bundle builds the objects while the big members are still being checked in the second
    thread (read_bundle_deferred): bytes gone bad on disk in the stored blocks, which also break the
    blocks' own check (a morph slot out of range), are still reported as the corrupt member they are
    (its SHA-256 when verifying, the zip's CRC-32 when not), never as invalid blocks."""
    from piste.formats import bundle as fmt

    monkeypatch.setattr(fmt._Hasher, "MIN_BYTES", 0)  # (the mini bundle's blocks are small)
    path, net = _bundle(tmp_path)
    b = load_bundle(path, warm=True)  # (unchanged: loads)
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(RESIDENT_MEMBER + ".npy")
        start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
        head = len(zf.read(info.filename)) - b.arrays[RESIDENT_MEMBER].nbytes
    raw = bytearray(path.read_bytes())
    at = start + head + (5 * 11 + 10) * 4  # vertex 5's morph slot (float32)
    raw[at:at + 4] = np.float32(1e6).tobytes()
    bad = tmp_path / "rot.piste"
    bad.write_bytes(bytes(raw))
    for verify in (True, False):
        with pytest.raises(FormatError, match="corrupt member") as e:
            load_bundle(bad, verify=verify, warm=True)
        assert e.value.field == RESIDENT_MEMBER + ".npy"
