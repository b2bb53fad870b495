"""Damaged bundle manifests (issue 10 item 3): wrong types, missing keys, deep nesting and absurd
member sizes are FormatErrors naming the bundle, never KeyError / int('eight') / RecursionError."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bundle import write_bundle
from piste.pipeline.bundle_objects import load_bundle

ARRAYS = {"terrain/control_points": np.zeros((1, 4, 4, 3)), "terrain/uv": np.zeros((1, 2, 4)),
          "lightmap/atlas": np.zeros((4, 4, 3), np.float32), "lightmap/rects": np.zeros((1, 4), np.float32)}


def _bundle(tmp_path, manifest_text_or_edit):
    p = tmp_path / "b.piste"
    write_bundle(p, {"name": "t"}, ARRAYS)
    with zipfile.ZipFile(p) as zf:
        parts = {n: zf.read(n) for n in zf.namelist()}
    man = json.loads(parts["manifest.json"])
    if callable(manifest_text_or_edit):
        manifest_text_or_edit(man)
        parts["manifest.json"] = json.dumps(man).encode()
    else:
        parts["manifest.json"] = manifest_text_or_edit
    q = tmp_path / "bad.piste"
    with zipfile.ZipFile(q, "w") as zf:
        for n, d in parts.items():
            zf.writestr(n, d)
    return q


@pytest.mark.parametrize("edit, field", [
    (lambda m: m.update(visibility={"shape": "eight", "cell": 1.0}), "visibility.shape"),
    (lambda m: m.update(visibility={"cell": 1.0, "shape": [2, 2]}), "manifest.json"),  # no 'origin'
    (lambda m: m.update(lightmap={"res": "eight"}), "lightmap.res"),
    (lambda m: m.update(cameras=[{"name": "c", "eye": [0, 0], "target": [1, 1, 1]}]), "cameras[0].eye"),
    (lambda m: m.update(lights={"directional": [{"direction": [0, 0, -1], "intensity": 1e308}]}), "intensity"),
    (lambda m: m["members"].update({"terrain/uv": None}), "members.terrain/uv"),
    (lambda m: m["members"]["terrain/uv"].update(shape=[10**9, 10**9]), "members.terrain/uv"),
    (lambda m: m.update(objects={"kinds": ["tree"]}), "manifest.json"),
])
def test_damaged_manifest_is_a_format_error(tmp_path, edit, field):
    with pytest.raises(FormatError) as ei:
        b = load_bundle(_bundle(tmp_path, edit))
        b.objects()
    assert "bad.piste" in str(ei.value) and field in str(ei.value), str(ei.value)


def test_deeply_nested_manifest(tmp_path):
    text = b'{"format": "piste.bundle/1", "members": {}, "x": ' + b"[" * 100_000 + b"]" * 100_000 + b"}"
    with pytest.raises(FormatError, match=r"bad\.piste.*nested too deeply"):
        load_bundle(_bundle(tmp_path, text))


def test_disabled_visibility_null_section_loads(tmp_path):
    b = load_bundle(_bundle(tmp_path, lambda m: m.update(visibility=None)))
    assert b.visibility is None
