"""Fuzz glTF / GLB loading: real models mutated byte-wise and structurally (JSON fields replaced by
wrong types, huge and negative numbers, hostile URIs, deep nesting).  Each case loads or raises a
PisteError naming the file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import json
import shutil
import struct

import pytest
from fuzzlib import DATA, EXAMPLES, byte_mutations, check, doc_mutations, dump_json, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.formats import load_gltf

SEEDS = [p for p in [DATA / "gltf" / "SimpleSkin" / "SimpleSkin.gltf", DATA / "gltf" / "SimpleMorph" / "SimpleMorph.gltf",
                     DATA / "gltf" / "MorphPrimitivesTest" / "MorphPrimitivesTest.gltf",
                     DATA / "gltf" / "AnimatedMorphCube" / "AnimatedMorphCube.glb",
                     DATA / "gltf" / "RiggedSimple" / "RiggedSimple.glb",
                     EXAMPLES / "scenes" / "assets" / "lights_cameras.gltf"] if p.exists()]
IDS = [p.name for p in SEEDS]


def _glb_parts(data: bytes):
    """(json dict, binary chunk or None) of a GLB."""
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + jlen])
    rest = data[20 + jlen:]
    return doc, (rest[8:] if len(rest) >= 8 else None)


def _glb(doc_bytes: bytes, blob) -> bytes:
    doc_bytes += b" " * (-len(doc_bytes) % 4)
    body = struct.pack("<II", len(doc_bytes), 0x4E4F534A) + doc_bytes
    if blob is not None:
        body += struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


@pytest.fixture(params=SEEDS, ids=IDS)
def seed(request, tmp_path_factory):
    """The seed model copied with its folder (buffers, images) into a fresh folder."""
    d = tmp_path_factory.mktemp("gltf")
    for f in request.param.parent.iterdir():
        if f.is_file():
            shutil.copy(f, d / f.name)
    return d / request.param.name


@pytest.mark.skipif(not SEEDS, reason="no seed models")
def test_seeds_load(seed):
    assert check(load_gltf, seed, "gltf seeds") == "loaded"


@pytest.mark.skipif(not SEEDS, reason="no seed models")
@given(data=st.data())
@fuzz_settings(20)
def test_gltf_bytes(seed, data):
    original = seed.read_bytes()
    mutated = data.draw(byte_mutations(original))
    target = seed.with_name("mutant" + seed.suffix)
    target.write_bytes(mutated)
    check(load_gltf, target, "gltf byte-wise")


@pytest.mark.skipif(not SEEDS, reason="no seed models")
@given(data=st.data())
@fuzz_settings(50)
def test_gltf_structure(seed, data):
    original = seed.read_bytes()
    if seed.suffix == ".glb":
        doc, blob = _glb_parts(original)
        mutated = _glb(dump_json(data.draw(doc_mutations(doc))), blob)
    else:
        mutated = dump_json(data.draw(doc_mutations(json.loads(original))))
    target = seed.with_name("mutant" + seed.suffix)
    target.write_bytes(mutated)
    check(load_gltf, target, "gltf structural")
