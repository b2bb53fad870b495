"""Hostile glTF files (issue 10 items 3, 4): URIs confined to the model's folder, special files
refused without being opened, sizes and counts capped before anything is allocated."""

from __future__ import annotations

import base64
import json
import os
import struct
import threading

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats import limits, load_gltf, safe_io

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()  # 36 bytes


def write_model(folder, uri, byte_length=36, name="m.gltf", extra=None):
    """A one-triangle glTF in ``folder`` whose only buffer is ``uri``."""
    folder.mkdir(parents=True, exist_ok=True)
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"uri": uri, "byteLength": byte_length}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    if extra:
        doc.update(extra)
    p = folder / name
    p.write_text(json.dumps(doc))
    return p


def test_relative_buffer_inside_folder_loads(tmp_path):
    (tmp_path / "m" / "sub").mkdir(parents=True)
    (tmp_path / "m" / "sub" / "tri.bin").write_bytes(TRI)
    m = load_gltf(write_model(tmp_path / "m", "sub/../sub/tri%2Ebin"))
    assert m.n_triangles == 1


@pytest.mark.parametrize("uri", ["../secret.bin", "sub/../../secret.bin", "%2E%2E/secret.bin"])
def test_dotdot_escape_refused(tmp_path, uri):
    (tmp_path / "secret.bin").write_bytes(TRI)
    (tmp_path / "m" / "sub").mkdir(parents=True)
    with pytest.raises(FormatError, match=r"m\.gltf, field 'buffers\[0\]\.uri'.*leaves the model's folder"):
        load_gltf(write_model(tmp_path / "m", uri))


def test_absolute_path_refused_and_allow_paths_allows(tmp_path):
    (tmp_path / "assets").mkdir()
    secret = tmp_path / "assets" / "tri.bin"
    secret.write_bytes(TRI)
    p = write_model(tmp_path / "m", str(secret))
    with pytest.raises(FormatError, match="absolute path"):
        load_gltf(p)
    assert load_gltf(p, allow_paths=[tmp_path / "assets"]).n_triangles == 1
    # a sibling folder through '..' is allowed when named, and only then
    p2 = write_model(tmp_path / "m", "../assets/tri.bin", name="m2.gltf")
    with pytest.raises(FormatError, match="leaves the model's folder"):
        load_gltf(p2)
    assert load_gltf(p2, allow_paths=[tmp_path / "assets"]).n_triangles == 1
    with pytest.raises(FormatError, match="leaves the model's folder"):
        load_gltf(p2, allow_paths=[tmp_path / "elsewhere"])


def test_file_url_refused(tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "tri.bin").write_bytes(TRI)
    with pytest.raises(FormatError, match="is a URL"):
        load_gltf(write_model(tmp_path / "m", "file:tri.bin"))


def test_symlink_refused(tmp_path):
    """No link is followed below the model's folder (issue 24): one pointing out is refused, and so
    is one that stays inside (a link could be swapped for another between the check and the read)."""
    (tmp_path / "secret.bin").write_bytes(TRI + b"PRIVATE KEY")
    (tmp_path / "m").mkdir()
    os.symlink(tmp_path / "secret.bin", tmp_path / "m" / "tri.bin")
    with pytest.raises(FormatError, match="symbolic link") as ei:
        load_gltf(write_model(tmp_path / "m", "tri.bin"))
    assert "PRIVATE" not in str(ei.value)
    (tmp_path / "m" / "real.bin").write_bytes(TRI)
    os.symlink("real.bin", tmp_path / "m" / "inner.bin")
    with pytest.raises(FormatError, match="symbolic link"):
        load_gltf(write_model(tmp_path / "m", "inner.bin", name="ok.gltf"))
    assert load_gltf(write_model(tmp_path / "m", "real.bin", name="ok2.gltf")).n_triangles == 1


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_fifo_refused_without_opening(tmp_path):
    (tmp_path / "m").mkdir()
    os.mkfifo(tmp_path / "m" / "tri.bin")
    result = {}

    def go():
        try:
            load_gltf(write_model(tmp_path / "m", "tri.bin"))
        except FormatError as e:
            result["e"] = e

    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():  # unblock the reader so the test process can exit, then fail
        fd = os.open(tmp_path / "m" / "tri.bin", os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        pytest.fail("load_gltf blocked on a named pipe")
    assert "not a regular file" in str(result["e"])


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_device_refused(tmp_path):
    with pytest.raises(FormatError, match="absolute path"):
        load_gltf(write_model(tmp_path / "m", "/dev/zero"))
    with pytest.raises(FormatError, match="not a regular file"):
        load_gltf(write_model(tmp_path / "m", "/dev/zero"), allow_paths=["/dev"])
    (tmp_path / "m2").mkdir()
    os.symlink("/dev/zero", tmp_path / "m2" / "z.bin")
    with pytest.raises(FormatError, match="symbolic link"):
        load_gltf(write_model(tmp_path / "m2", "z.bin"), allow_paths=["/dev"])


def test_folder_as_buffer_refused(tmp_path):
    (tmp_path / "m" / "d").mkdir(parents=True)
    with pytest.raises(FormatError, match="not a regular file"):
        load_gltf(write_model(tmp_path / "m", "d"))


@pytest.mark.parametrize("n", [-1, 2**40, True, None])
def test_byte_length_checked_before_reading(tmp_path, n):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "tri.bin").write_bytes(TRI)
    with pytest.raises(FormatError, match=r"buffers\[0\]\.byteLength"):
        load_gltf(write_model(tmp_path / "m", "tri.bin", byte_length=n))


def test_huge_data_uri_refused_before_decoding(tmp_path, monkeypatch):
    monkeypatch.setattr(safe_io, "MAX_BUFFER_BYTES", 1000)
    uri = "data:application/octet-stream;base64," + base64.b64encode(TRI * 100).decode()
    with pytest.raises(FormatError, match=r"buffers\[0\]\.byteLength"):
        load_gltf(write_model(tmp_path / "m", uri, byte_length=3600))
    # a data URI much longer than its byteLength is refused from its text length
    with pytest.raises(FormatError, match=r"data URI holds about"):
        load_gltf(write_model(tmp_path / "m", uri, byte_length=36, name="b.gltf"))


def test_only_byte_length_bytes_are_read(tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "tri.bin").write_bytes(TRI + b"\xff" * 1000)
    assert load_gltf(write_model(tmp_path / "m", "tri.bin")).n_triangles == 1


def test_image_uri_confined(tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "tri.bin").write_bytes(TRI)
    extra = {"images": [{"uri": "../x.png"}], "textures": [{"source": 0}],
             "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]}
    p = write_model(tmp_path / "m", "tri.bin", extra=extra)
    doc = json.loads(p.read_text())
    doc["meshes"][0]["primitives"][0]["material"] = 0
    p.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=r"images\[0\]\.uri.*leaves the model's folder"):
        load_gltf(p)


def test_image_pixel_cap_checked_before_decoding(tmp_path, monkeypatch):
    from PIL import Image

    monkeypatch.setattr(safe_io, "MAX_IMAGE_PIXELS", 100)
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "tri.bin").write_bytes(TRI)
    Image.new("RGB", (20, 20)).save(tmp_path / "m" / "t.png")
    extra = {"images": [{"uri": "t.png"}], "textures": [{"source": 0}],
             "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]}
    p = write_model(tmp_path / "m", "tri.bin", extra=extra)
    doc = json.loads(p.read_text())
    doc["meshes"][0]["primitives"][0]["material"] = 0
    p.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=r"images\[0\].*400 pixels|images\[0\].*20 x 20"):
        load_gltf(p)


def test_node_count_capped(tmp_path, monkeypatch):
    monkeypatch.setattr(limits, "MAX_GLTF_NODES", 10)
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "tri.bin").write_bytes(TRI)
    p = write_model(tmp_path / "m", "tri.bin", extra={"nodes": [{}] * 11})
    with pytest.raises(FormatError, match=r"field 'nodes'.*limit of 10"):
        load_gltf(p)


def test_deep_json_nesting_refused(tmp_path):
    (tmp_path / "m").mkdir()
    p = tmp_path / "m" / "deep.gltf"
    p.write_text('{"asset": {"version": "2.0"}, "extras": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(FormatError, match="nested too deeply"):
        load_gltf(p)


def test_glb_chunk_length_past_end_refused(tmp_path):
    js = json.dumps({"asset": {"version": "2.0"}}).encode()
    js += b" " * (-len(js) % 4)
    glb = struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(js)) + struct.pack("<II", len(js) + 10**9, 0x4E4F534A) + js
    p = tmp_path / "bad.glb"
    p.write_bytes(glb)
    with pytest.raises(FormatError, match=r"bad\.glb, field 'chunk0.length'"):
        load_gltf(p)


def test_200k_nodes_refused_before_parsing(tmp_path):
    p = tmp_path / "many.gltf"
    p.write_text(json.dumps({"asset": {"version": "2.0"}, "nodes": [{}] * 200_000}))
    with pytest.raises(FormatError, match=r"many\.gltf, field 'nodes': count 200000 is more than the limit"):
        load_gltf(p)


def test_huge_number_arrays_refused_before_walking(tmp_path):
    p = tmp_path / "big.gltf"
    p.write_text(json.dumps({"asset": {"version": "2.0"}, "accessors": [{"max": [0] * 2_000_000}]}))
    with pytest.raises(FormatError, match=r"big\.gltf: more than .* values"):
        load_gltf(p)


@pytest.mark.parametrize("doc, field", [
    ({"scenes": "red"}, "scenes"), ({"scene": True}, "scene"), ({"nodes": [{"mesh": -1}]}, "nodes[0].mesh"),
    ({"nodes": [{"translation": [1, 2]}]}, "nodes[0].translation"), ({"accessors": [{"count": "eight"}]},
                                                                         "accessors[0].count"),
    ({"meshes": [{"primitives": [{"attributes": {"POSITION": 1.5}}]}]}, "meshes[0].primitives[0].attributes.POSITION"),
    ({"cameras": [{"perspective": {"yfov": None}}]}, "cameras[0].perspective.yfov"),
])
def test_wrong_json_types_name_the_field(tmp_path, doc, field):
    p = tmp_path / "t.gltf"
    p.write_text(json.dumps({"asset": {"version": "2.0"}, **doc}))
    with pytest.raises(FormatError) as ei:
        load_gltf(p)
    assert f"t.gltf, field {field!r}" in str(ei.value)
