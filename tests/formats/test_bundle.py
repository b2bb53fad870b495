"""The .piste bundle: round trip, determinism, and clear errors on wrong versions and corrupt files."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bundle import BUNDLE_FORMAT, BundleData, read_bundle, read_manifest, write_bundle


def _minimal(tmp_path, name="b.piste", manifest=None):
    from piste.terrain.net import PatchNet

    g = np.zeros((7, 7, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(7.0))
    g[..., 2] = 0.1 * g[..., 0]
    net = PatchNet.from_control_grid(g)
    arrays = {
        "terrain/control_points": net.control_points,
        "terrain/uv": net.uv,
        "lightmap/atlas": np.full((20, 20, 3), 0.5, np.float32),
        "lightmap/rects": net.lightmap_rect,
    }
    man = {"name": "mini", "terrain": {"name": "mini", "tol": net.tol},
           "lights": {"ambient": [{"color": [1.0, 1.0, 1.0], "intensity": 0.5, "name": ""}],
                      "point": [{"position": [0.0, 0.0, 1.0], "color": [1.0, 1.0, 1.0], "intensity": 1.0, "range": "inf",
                                 "falloff": 1.0, "shadows": True, "name": "p"}]},
           "cameras": [{"name": "c", "eye": [0.0, -5.0, 5.0], "target": [3.0, 3.0, 0.0], "up": [0.0, 0.0, 1.0],
                        "fov_y": 50.0, "near": 0.1, "far": 100.0, "ortho_height": None}],
           "lightmap": {"res": 8, "gutter": 1}}
    if manifest:
        man.update(manifest)
    return write_bundle(tmp_path / name, man, arrays), arrays


def test_round_trip(tmp_path):
    path, arrays = _minimal(tmp_path)
    b = read_bundle(path)
    assert isinstance(b, BundleData) and b.path == path
    assert b.manifest["format"] == BUNDLE_FORMAT == read_manifest(path)["format"]
    assert sorted(b.arrays) == sorted(arrays)
    for k, a in arrays.items():
        assert b.arrays[k].dtype == np.asarray(a).dtype and np.array_equal(b.arrays[k], a)
    assert b.manifest["cameras"][0]["fov_y"] == 50.0 and b.manifest["lights"]["point"][0]["range"] == "inf"
    m = b.manifest["members"]["lightmap/atlas"]
    assert m["shape"] == [20, 20, 3] and m["dtype"] == "<f4" and len(m["sha256"]) == 64


def test_members_keep_their_shapes(tmp_path):
    """A 0-d member comes back 0-d (np.ascontiguousarray would store it as shape (1,)), and a
    transposed (non-contiguous) one with its own shape and values."""
    from piste.terrain.net import PatchNet

    g = np.zeros((7, 7, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(7.0))
    net = PatchNet.from_control_grid(g)
    t = np.arange(12, dtype=np.float32).reshape(3, 4).T
    arrays = {"terrain/control_points": net.control_points, "terrain/uv": net.uv,
              "lightmap/atlas": np.full((4, 4, 3), 0.5, np.float32), "lightmap/rects": net.lightmap_rect,
              "extra/scalar": np.float32(2.5), "extra/transposed": t}
    path = write_bundle(tmp_path / "s.piste", {"name": "s", "terrain": {"name": "s", "tol": net.tol}}, arrays)
    b = read_bundle(path)
    assert b.manifest["members"]["extra/scalar"]["shape"] == []
    assert b.arrays["extra/scalar"].shape == () and float(b.arrays["extra/scalar"]) == 2.5
    assert b.arrays["extra/transposed"].shape == (4, 3) and np.array_equal(b.arrays["extra/transposed"], t)


def test_load_bundle_here_is_deprecated(tmp_path):
    """``piste.formats.bundle.load_bundle`` still works (manifest and arrays) but points to the
    pipeline's loader, which builds the scene objects; the moved names say where they went."""
    import piste.formats.bundle as fb

    path, _ = _minimal(tmp_path)
    with pytest.warns(DeprecationWarning, match="piste.pipeline.load_bundle"):
        b = fb.load_bundle(path)
    assert isinstance(b, BundleData) and "terrain/uv" in b.arrays
    with pytest.raises(AttributeError, match="piste.pipeline"):
        fb.Bundle  # noqa: B018


def test_same_content_same_bytes(tmp_path):
    a, _ = _minimal(tmp_path, "a.piste")
    b, _ = _minimal(tmp_path, "b.piste")
    assert a.read_bytes() == b.read_bytes()


def test_wrong_version(tmp_path):
    path, _ = _minimal(tmp_path)
    with zipfile.ZipFile(path) as zf:
        items = {n: zf.read(n) for n in zf.namelist()}
    man = json.loads(items["manifest.json"])
    man["format"] = "piste.bundle/99"
    items["manifest.json"] = json.dumps(man).encode()
    bad = tmp_path / "v99.piste"
    with zipfile.ZipFile(bad, "w") as zf:
        for n, d in items.items():
            zf.writestr(n, d)
    with pytest.raises(FormatError, match="piste.bundle/99.*rebuild") as info:
        read_bundle(bad)
    assert info.value.field == "format" and info.value.path == str(bad)


def test_corrupt_member(tmp_path):
    path, _ = _minimal(tmp_path)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("lightmap/atlas.npy")
    # flip bytes inside the member's compressed data
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 10
    for i in range(start, start + 8):
        data[i] ^= 0xFF
    bad = tmp_path / "corrupt.piste"
    bad.write_bytes(bytes(data))
    with pytest.raises(FormatError) as e:
        read_bundle(bad)
    assert "lightmap/atlas.npy" in str(e.value)


def test_not_a_bundle(tmp_path):
    (tmp_path / "x.piste").write_bytes(b"hello")
    with pytest.raises(FormatError, match="not a zip"):
        read_bundle(tmp_path / "x.piste")
    with pytest.raises(FormatError, match="no such file"):
        read_bundle(tmp_path / "missing.piste")
    with zipfile.ZipFile(tmp_path / "empty.piste", "w") as zf:
        zf.writestr("other.txt", "x")
    with pytest.raises(FormatError, match="no manifest.json"):
        read_bundle(tmp_path / "empty.piste")


def test_missing_member_and_checksum(tmp_path):
    path, _ = _minimal(tmp_path)
    with zipfile.ZipFile(path) as zf:
        items = {n: zf.read(n) for n in zf.namelist()}
    dropped = dict(items)
    del dropped["lightmap/rects.npy"]
    with zipfile.ZipFile(tmp_path / "drop.piste", "w") as zf:
        for n, d in dropped.items():
            zf.writestr(n, d)
    with pytest.raises(FormatError, match="missing") as e:
        read_bundle(tmp_path / "drop.piste")
    assert e.value.field == "lightmap/rects.npy"
    # a member replaced by another valid array: zip CRC fine, the manifest's SHA-256 catches it
    import io

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.zeros((20, 20, 3), np.float32))
    swapped = dict(items)
    swapped["lightmap/atlas.npy"] = buf.getvalue()
    with zipfile.ZipFile(tmp_path / "swap.piste", "w") as zf:
        for n, d in swapped.items():
            zf.writestr(n, d)
    with pytest.raises(FormatError, match="checksum"):
        read_bundle(tmp_path / "swap.piste")
    assert read_bundle(tmp_path / "swap.piste", verify=False).arrays["lightmap/atlas"].max() == 0.0


def test_write_is_atomic(tmp_path, monkeypatch):
    path, _ = _minimal(tmp_path)
    before = path.read_bytes()
    with pytest.raises(FormatError):
        write_bundle(path, {"name": "x"}, {"bad": np.array([object()], dtype=object)})
    assert path.read_bytes() == before
    assert not list(tmp_path.glob(".*.tmp"))
