"""``bake_lightmap`` as a pipeline step: deterministic bytes, resuming, process pool, files, CLI,
and the renderer's cached default light map."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from lighting_nets import hill_net, make_lights

from piste.cli import main
from piste.errors import FormatError
from piste.lighting import Lights, PointLight, bake_lightmap, dumps_lights, load_lightmap, load_or_bake_default_lightmap, write_lightmap
from piste.lighting import baker as baker_mod

FILES = ("lightmap.png", "lightmap.npz", "manifest.json")
DATA = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))


def _bytes(folder):
    return {name: (folder / name).read_bytes() for name in FILES}


class Stop(Exception):
    pass


def test_same_input_same_bytes(tmp_path, hill, lights):
    lights = lights + Lights((PointLight((5.0, 5.0, 20.0), (0.2, 0.2, 0.2), 0.3),))  # range inf
    for k in range(2):
        write_lightmap(bake_lightmap(hill, lights, res=8, chunk_size=2), tmp_path / f"run{k}")
    assert _bytes(tmp_path / "run0") == _bytes(tmp_path / "run1")
    manifest = json.loads((tmp_path / "run0" / "manifest.json").read_text())
    assert manifest["patches"] == 9 and manifest["res"] == 8 and manifest["samples"] == 9 * 64
    assert set(manifest["files"]) == {"lightmap.png", "lightmap.npz"}
    text = (tmp_path / "run0" / "manifest.json").read_text()
    assert "Infinity" not in text and '"inf"' in text  # the sun-like point light of range inf


def test_resume_after_interruption_gives_identical_bytes(tmp_path, lights):
    net = hill_net(4, 3)
    reference = bake_lightmap(net, lights, res=8, chunk_size=2)
    write_lightmap(reference, tmp_path / "reference")

    calls = []

    def hook(chunk, done, total):
        calls.append(chunk)
        if len(calls) == 3:
            raise Stop

    partial = tmp_path / "out" / ".partial"
    with pytest.raises(Stop):
        bake_lightmap(net, lights, res=8, chunk_size=2, partial_dir=partial, on_chunk=hook)
    stored = sorted(p.name for p in partial.rglob("chunk_*.npy"))
    assert len(stored) == 3

    redone = []
    lm = bake_lightmap(net, lights, res=8, chunk_size=2, partial_dir=partial, on_chunk=lambda c, d, t: redone.append(c))
    assert lm.resumed_chunks == 3 and len(redone) == 6 - 3 and not set(redone) & set(calls)
    write_lightmap(lm, tmp_path / "out")
    assert _bytes(tmp_path / "out") == _bytes(tmp_path / "reference")


def test_corrupt_partial_chunk_is_redone(tmp_path, hill, lights):
    partial = tmp_path / ".partial"
    lm = bake_lightmap(hill, lights, res=8, chunk_size=4, partial_dir=partial)
    files = sorted(partial.rglob("chunk_*.npy"))
    files[0].write_bytes(b"garbage")
    again = bake_lightmap(hill, lights, res=8, chunk_size=4, partial_dir=partial)
    assert again.resumed_chunks == len(files) - 1
    np.testing.assert_array_equal(again.atlas, lm.atlas)


def test_process_pool_matches_in_process(tmp_path, lights):
    net = hill_net(3, 2)
    one = bake_lightmap(net, lights, res=8, chunk_size=2, jobs=1)
    two = bake_lightmap(net, lights, res=8, chunk_size=2, jobs=2)
    np.testing.assert_array_equal(one.atlas, two.atlas)
    assert one.manifest == two.manifest


def test_inputs_change_the_key(hill, lights):
    a = bake_lightmap(hill, lights, res=8, shadows=False).manifest["key"]
    assert bake_lightmap(hill, lights, res=16, shadows=False).manifest["key"] != a
    moved = hill_net(relief=3.5)
    assert bake_lightmap(moved, lights, res=8, shadows=False).manifest["key"] != a


def test_write_and_load(tmp_path, hill, lights):
    lm = bake_lightmap(hill, lights, res=16)
    write_lightmap(lm, tmp_path)
    back = load_lightmap(tmp_path)
    np.testing.assert_array_equal(back.atlas, lm.atlas)
    np.testing.assert_array_equal(back.rects, lm.rects)
    assert back.res == 16 and back.manifest["key"] == lm.manifest["key"]
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "lightmap.png"))
    np.testing.assert_array_equal(png, lm.to_uint8())
    assert not list(tmp_path.glob(".*.tmp"))  # no temporary files left behind
    (tmp_path / "manifest.json").write_text("{ not json")
    with pytest.raises(FormatError, match="manifest.json, line 1"):
        load_lightmap(tmp_path)


def test_cli_bake(tmp_path, capsys, lights):
    net = hill_net(2, 2)
    net.save(tmp_path / "net.npz")
    (tmp_path / "lights.toml").write_text(dumps_lights(lights))
    out = tmp_path / "baked"
    args = ["bake", str(tmp_path / "net.npz"), "--lights", str(tmp_path / "lights.toml"), "--res", "16", "--out", str(out), "--jobs", "1", "--quiet"]
    assert main(args) == 0
    assert "samples/s" in capsys.readouterr().out
    assert all((out / f).exists() for f in FILES)
    assert not (out / ".partial").exists()
    first = _bytes(out)
    assert main(args) == 0
    assert _bytes(out) == first
    # a .bpt net (the teapot) with the default lights
    teapot = DATA / "patches" / "teapot.bpt"
    if teapot.exists():
        assert main(["bake", str(teapot), "--out", str(tmp_path / "teapot"), "--no-shadows", "--quiet", "--jobs", "1"]) == 0
        assert json.loads((tmp_path / "teapot" / "manifest.json").read_text())["patches"] == 32


def test_cli_errors(tmp_path, capsys):
    (tmp_path / "bad.toml").write_text("[[point]]\nposition = [0, 0]\n")
    net = hill_net(1, 1)
    net.save(tmp_path / "net.npz")
    assert main(["bake", str(tmp_path / "net.npz"), "--lights", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "bad.toml, line 2" in err and "position" in err
    assert main(["bake", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "o")]) == 1
    assert "expected a .bpt or .npz" in capsys.readouterr().err


def test_load_or_bake_caches(tmp_path, monkeypatch, hill, lights):
    lm = load_or_bake_default_lightmap(hill, lights, res=8, cache_dir=tmp_path, jobs=1)
    entries = [p for p in tmp_path.iterdir() if not p.name.startswith(".")]
    assert len(entries) == 1 and (entries[0] / "manifest.json").exists()

    def no_bake(*a, **k):
        raise AssertionError("baked again instead of using the cache")

    monkeypatch.setattr(baker_mod, "bake_lightmap", no_bake)
    again = load_or_bake_default_lightmap(hill, lights, res=8, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.atlas, lm.atlas)
    net = again.apply(hill)
    np.testing.assert_array_equal(net.lightmap_rect, lm.rects)
