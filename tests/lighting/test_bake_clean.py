"""A failed bake says where its resumable chunks are and how much they hold, and ``piste bake
--clean`` removes them (issue 24 item 4)."""

from __future__ import annotations

import errno
import os
import re

import pytest
from lighting_nets import hill_net

from piste.cli import main
from piste.errors import OutputError
from piste.lighting import bake_lightmap, dumps_lights
from piste.lighting import baker as baker_mod
from piste.lighting.baker import clean_partials, partial_usage


@pytest.fixture
def bake_args(tmp_path, lights):
    net = hill_net(3, 3)
    net.save(tmp_path / "net.npz")
    (tmp_path / "lights.toml").write_text(dumps_lights(lights))
    out = tmp_path / "baked"
    return out, ["bake", str(tmp_path / "net.npz"), "--lights", str(tmp_path / "lights.toml"), "--res", "8",
                 "--out", str(out), "--jobs", "1", "--quiet", "--chunk-size", "2"]


def _files(folder):
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def test_full_disk_when_writing_says_where_the_chunks_are_and_clean_removes_them(bake_args, capsys, monkeypatch):
    out, args = bake_args

    def full(lm, out_dir):
        raise OSError(errno.ENOSPC, "No space left on device", str(out_dir / "lightmap.npz"))

    import piste.lighting as lighting

    # piste.lighting's lazy export first: read after baker's is patched, it would save the patched
    # function as the one to restore, and the next test's bake would still fail
    monkeypatch.setattr(lighting, "write_lightmap", full)
    monkeypatch.setattr(baker_mod, "write_lightmap", full)
    assert main(args) == 1
    err = capsys.readouterr().err
    part = out / ".partial"
    chunks, size = partial_usage(part)
    assert chunks == 5 and size > 5 * 8 * 8 * 3 * 4  # 9 patches in chunks of 2; float32 texels
    assert err.count("\n") == 1
    assert f"piste bake: error: {part}: the bake stopped (" in err
    assert "lightmap.npz: no space left on the device (disk full)" in err
    assert f"its 5 finished chunks ({size:,} bytes) are kept here" in err and "piste bake --clean" in err
    monkeypatch.undo()

    (part / "notes.txt").write_text("not the baker's")  # a file of someone else's is left alone
    assert main([*args, "--clean"]) == 0
    assert capsys.readouterr().out.strip() == f"removed 5 resumable chunks ({size:,} bytes) from {part}"
    assert _files(out) == [part.relative_to(out) / "notes.txt"]
    (part / "notes.txt").unlink()
    assert main([*args, "--clean"]) == 0
    assert capsys.readouterr().out.strip() == f"no resumable chunks in {part}"


def test_resume_after_the_failure_gives_the_same_bytes(bake_args, capsys, monkeypatch, tmp_path):
    out, args = bake_args
    ref = tmp_path / "ref"
    assert main([str(ref) if a == str(out) else a for a in args]) == 0
    import piste.lighting as lighting

    def full(lm, out_dir):
        raise OSError(errno.ENOSPC, "No space left on device", str(out_dir / "lightmap.npz"))

    monkeypatch.setattr(lighting, "write_lightmap", full)
    assert main(args) == 1
    monkeypatch.undo()
    assert main(args) == 0
    assert "5 chunks resumed" in capsys.readouterr().out
    for name in ("lightmap.png", "lightmap.npz", "manifest.json"):
        assert (out / name).read_bytes() == (ref / name).read_bytes()
    assert not (out / ".partial").exists()


def test_an_error_while_baking_names_the_kept_chunks(tmp_path, hill, lights, monkeypatch):
    """Not a full disk (an I/O error on the 4th chunk): the 3 finished chunks stay for a resume and the
    error says where, how many and how big."""
    part = tmp_path / ".partial"
    real = baker_mod._save_npy_atomic
    calls = {"n": 0}

    def flaky(path, arr):
        calls["n"] += 1
        if calls["n"] == 4:
            raise OutputError(path, "input/output error") from OSError(errno.EIO, "Input/output error")
        return real(path, arr)

    monkeypatch.setattr(baker_mod, "_save_npy_atomic", flaky)
    with pytest.raises(OutputError) as exc:
        bake_lightmap(hill, lights, res=8, chunk_size=1, partial_dir=part)
    chunks, size = partial_usage(part)
    assert chunks == 3
    msg = str(exc.value)
    (key,) = [d.name for d in part.iterdir()]  # this bake's folder (its inputs' key) is named
    assert msg.startswith(f"{part / key}: the bake stopped (") and "chunk_00003.npy: input/output error" in msg
    assert f"its 3 finished chunks ({size:,} bytes) are kept here" in msg


def test_full_disk_while_baking_says_what_it_removed(tmp_path, hill, lights, monkeypatch):
    part = tmp_path / ".partial"
    real = baker_mod._save_npy_atomic
    calls = {"n": 0}

    def filling(path, arr):
        calls["n"] += 1
        if calls["n"] == 4:
            raise OutputError(path, "no space left on the device (disk full)") from OSError(errno.ENOSPC, "full")
        return real(path, arr)

    monkeypatch.setattr(baker_mod, "_save_npy_atomic", filling)
    with pytest.raises(OutputError) as exc:
        bake_lightmap(hill, lights, res=8, chunk_size=1, partial_dir=part)
    assert re.fullmatch(re.escape(f"{part}/") + r"[0-9a-f]{64}: the bake stopped \(.*chunk_00003\.npy: no space left "
                        r"on the device \(disk full\)\); its 3 finished chunks \([\d,]+ bytes\) were removed from "
                        r"here to free the space", str(exc.value))
    assert partial_usage(part) == (0, 0)


def test_clean_does_not_follow_links(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "chunk_00000.npy").write_bytes(b"x" * 100)
    out = tmp_path / "o"
    out.mkdir()
    os.symlink(outside, out / ".partial")
    assert partial_usage(out / ".partial") == (0, 0)
    assert clean_partials(out / ".partial") == (0, 0)
    (out / ".partial").unlink()
    (out / ".partial" / "k").mkdir(parents=True)
    os.symlink(outside, out / ".partial" / "k" / "link")
    os.symlink(outside / "chunk_00000.npy", out / ".partial" / "k" / "chunk_00001.npy")
    assert partial_usage(out / ".partial") == (0, 0)
    clean_partials(out / ".partial")
    assert (outside / "chunk_00000.npy").read_bytes() == b"x" * 100


BUILD_SCENE = """\
[terrain]
source = "dem.npz"
[lightmap]
res = 4
shadows = false
[visibility]
enabled = false
"""


def test_failed_build_names_piste_build_clean_which_removes_only_the_chunks(tmp_path, capsys, monkeypatch):
    """``piste build``'s bake keeps its finished chunks in CACHE/bake-partial when it fails; the
    message names them and ``piste build --clean SCENE``, which removes the baker's files only."""
    import numpy as np

    n = 65  # 16 x 16 = 256 patches: 4 chunks of 64
    y, x = np.mgrid[0:n, 0:n] * 10.0
    np.savez(tmp_path / "dem.npz", z=5.0 * np.sin(x / 70.0) * np.cos(y / 90.0), dx=np.float64(10.0))
    scene = tmp_path / "s.toml"
    scene.write_text(BUILD_SCENE)
    real = baker_mod._save_npy_atomic
    calls = {"n": 0}

    def flaky(path, arr):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OutputError(path, "input/output error") from OSError(errno.EIO, "Input/output error")
        return real(path, arr)

    monkeypatch.setattr(baker_mod, "_save_npy_atomic", flaky)
    assert main(["build", str(scene), "--quiet"]) == 1
    monkeypatch.undo()
    err = capsys.readouterr().err
    part = tmp_path / ".piste-cache" / "bake-partial"
    chunks, size = partial_usage(part)
    assert chunks == 2 and err.count("\n") == 1
    assert f"its 2 finished chunks ({size:,} bytes) are kept here" in err
    assert f"`piste build --clean {scene}`" in err and "piste bake --clean" not in err

    (part / "notes.txt").write_text("not the baker's")  # someone else's file stays
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "chunk_00000.npy").write_bytes(b"x" * 100)
    os.symlink(outside, part / "link")  # a link is not followed
    assert main(["build", "--clean", str(scene)]) == 0
    assert capsys.readouterr().out.strip() == f"removed 2 resumable chunks ({size:,} bytes) from {part}"
    assert partial_usage(part) == (0, len("not the baker's"))
    assert sorted(p.name for p in part.iterdir()) == ["link", "notes.txt"]
    assert (outside / "chunk_00000.npy").read_bytes() == b"x" * 100
    assert main(["build", str(scene), "--clean", "--cache", str(tmp_path / "elsewhere")]) == 0
    assert capsys.readouterr().out.strip() == f"no resumable chunks in {tmp_path / 'elsewhere' / 'bake-partial'}"
