"""Hostile files, each kind in a child process with a hard memory cap (RLIMIT_AS) and a time limit:
the cases whose failure mode is to exhaust memory or hang (huge declared counts, decompression
bombs, device and pipe references, deep nesting) must be refused with a PisteError naming the file,
and the child must neither be killed for memory nor run out of time."""

from __future__ import annotations

import io
import json
import os
import resource
import struct
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest

CHILD = Path(__file__).with_name("isolated_child.py")
MEMORY = 3 << 30  # address space of the child: piste + numpy + pygltflib need ~1.5 GiB of it
TIMEOUT = 120


def _png(w, h):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


def _gltf(uri, n=36):
    return json.dumps({"asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": n}],
                       "bufferViews": [{"buffer": 0, "byteLength": 36}],
                       "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
                       "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}]})


def hostile_files(d: Path) -> list:
    cases = []

    def add(kind, name, data):
        p = d / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
        cases.append((kind, str(p)))

    (d / "secret.key").write_text("-----BEGIN PRIVATE KEY-----\n")
    add("gltf", "m/up.gltf", _gltf("../secret.key"))
    add("gltf", "m/abs.gltf", _gltf(str(d / "secret.key")))
    add("gltf", "m/zero.gltf", _gltf("/dev/zero", 2**30))
    add("gltf", "m/urandom.gltf", _gltf("/dev/urandom", 2**40))
    if hasattr(os, "mkfifo"):
        os.mkfifo(d / "m" / "pipe.bin")
        add("gltf", "m/pipe.gltf", _gltf("pipe.bin"))
    add("gltf", "m/nodes.gltf", json.dumps({"asset": {"version": "2.0"}, "nodes": [{}] * 200_000}))
    add("gltf", "m/deep.gltf", '{"asset": {"version": "2.0"}, "extras": ' + "[" * 200_000 + "]" * 200_000 + "}")
    add("gltf", "m/glb.glb", struct.pack("<4sII", b"glTF", 2, 28) + struct.pack("<II", 2**31, 0x4E4F534A) + b"{}      ")
    add("gltf", "m/datauri.gltf", _gltf("data:application/octet-stream;base64," + "A" * (40 << 20), 36))
    add("bpt", "t/huge.bpt", "2000000000000\n3 3\n" + "0 0 0\n" * 16)
    add("heightfield", "h/bomb.png", _png(8000, 8000))
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": (300000, 300000)})
    zbuf = io.BytesIO()
    with zipfile.ZipFile(zbuf, "w") as zf:
        zf.writestr("z.npy", buf.getvalue())
    add("heightfield", "h/claims.npz", zbuf.getvalue())
    add("scene", "s/deep.toml", "x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    add("lights", "s/deep_lights.toml", "[[ambient]]\ncolor = " + "[" * 100_000 + "]" * 100_000 + "\n")
    man = {"format": "piste.bundle/1", "members": {"terrain/control_points": {"shape": [10**9, 10**9], "dtype": "<f8",
                                                                              "sha256": "0"}}}
    zbuf = io.BytesIO()
    with zipfile.ZipFile(zbuf, "w") as zf:
        zf.writestr("manifest.json", json.dumps(man))
    add("bundle", "b/claims.piste", zbuf.getvalue())
    return cases


def _limit():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS and /dev files: Linux")
def test_hostile_files_in_a_memory_capped_child(tmp_path):
    cases = hostile_files(tmp_path)
    p = subprocess.run([sys.executable, str(CHILD), json.dumps(cases)], capture_output=True, text=True,
                       timeout=TIMEOUT, preexec_fn=_limit)
    assert p.returncode == 0, p.stderr[-2000:]
    results = [json.loads(line) for line in p.stdout.splitlines()]
    assert len(results) == len(cases), p.stderr[-2000:]
    for r in results:
        assert r["result"] == "refused", r
        assert Path(r["path"]).name in r["message"], r
        assert "PRIVATE KEY" not in r["message"]
