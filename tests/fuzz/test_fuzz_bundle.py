"""Fuzz .piste bundles made by `piste build` of a small scene: byte-wise mutants of the file and
structural mutants of its manifest (the JSON the SHA-256 sums do not cover), loaded as the scene's
objects (terrain, light map, lights, cameras, visibility, objects, the rider model and LODs).
Each case loads or raises a PisteError naming the file, under a time and a memory cap."""

from __future__ import annotations

import json
import zipfile

from fuzzlib import byte_mutations, check, doc_mutations, dump_json, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.pipeline.bundle_objects import load_bundle


def _load_everything(path):
    b = load_bundle(path)
    b.objects()
    b.vertex_colors()
    if b.manifest.get("riders"):
        b.rider_model()
        b.rider_lods()
    for name in b.cameras:
        cam = b.camera(name)
        if b.visibility is not None:
            b.visibility.patches_at(cam.eye)
            b.visibility.objects_at(cam.eye)


def _repack(src, manifest_bytes: bytes, dst):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", compression=zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = manifest_bytes if info.filename == "manifest.json" else zin.read(info.filename)
            zout.writestr(info.filename, data)


def test_seed_loads(small_bundle):
    assert check(_load_everything, small_bundle, "bundle seed") == "loaded"


@given(data=st.data())
@fuzz_settings(20)
def test_bundle_bytes(small_bundle, tmp_path_factory, data):
    target = tmp_path_factory.mktemp("b") / "mutant.piste"
    target.write_bytes(data.draw(byte_mutations(small_bundle.read_bytes())))
    check(_load_everything, target, "bundle byte-wise")


@given(data=st.data())
@fuzz_settings(100)
def test_bundle_manifest(small_bundle, tmp_path_factory, data):
    with zipfile.ZipFile(small_bundle) as zf:
        doc = json.loads(zf.read("manifest.json"))
    target = tmp_path_factory.mktemp("b") / "mutant.piste"
    _repack(small_bundle, dump_json(data.draw(doc_mutations(doc))), target)
    check(_load_everything, target, "bundle manifest")
