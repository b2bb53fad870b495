"""Consistency around faults (issue 10 item 6): a bake folder is whole or refused, workers die
with their parent, an error stops the workers at once, a full disk leaves no partial files."""

from __future__ import annotations

import errno
import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from lighting_nets import hill_net, make_lights

from piste.errors import FormatError
from piste.lighting import bake_lightmap, load_lightmap, write_lightmap
from piste.lighting import baker as baker_mod
from piste.formats import atomic as atomic_mod


def test_mixed_folder_is_refused(tmp_path, hill, lights):
    """New images beside the old manifest (a bake killed between its renames) are refused."""
    write_lightmap(bake_lightmap(hill, lights, res=8), tmp_path / "a")
    write_lightmap(bake_lightmap(hill, lights, res=16), tmp_path / "b")
    assert load_lightmap(tmp_path / "a").res == 8
    for name in ("lightmap.png", "lightmap.npz"):
        (tmp_path / "a" / name).write_bytes((tmp_path / "b" / name).read_bytes())
        with pytest.raises(FormatError, match=rf"{name}: does not match the SHA-256 sum in manifest.json"):
            load_lightmap(tmp_path / "a")


def test_interrupted_write_leaves_no_manifest(tmp_path, hill, lights, monkeypatch):
    out = tmp_path / "lm"
    write_lightmap(bake_lightmap(hill, lights, res=8), out)
    real = baker_mod.write_bytes_atomic

    def full_disk(path, data):
        if Path(path).name == "lightmap.npz":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(baker_mod, "write_bytes_atomic", full_disk)
    with pytest.raises(OSError):
        write_lightmap(bake_lightmap(hill, lights, res=8, shadows=False), out)
    # the new png is there, the old npz, and no manifest: refused as a whole
    with pytest.raises(FormatError, match="manifest.json: no such file"):
        load_lightmap(out)
    assert not list(out.glob(".*.tmp"))


def test_full_disk_in_atomic_writer_cleans_up_and_names_the_path(tmp_path, monkeypatch):
    from piste.errors import OutputError

    target = tmp_path / "x.bin"

    class FullFile:
        def __init__(self, *a, **k):
            pass

    def boom(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", boom)
    with pytest.raises(OutputError, match=r"x\.bin: cannot write: no space left on the device"):
        atomic_mod.write_bytes_atomic(target, b"data")
    assert not target.exists() and list(tmp_path.iterdir()) == []


def test_unwritable_output_folder_names_the_path(tmp_path):
    from piste.errors import OutputError

    if os.geteuid() == 0:
        blocker = tmp_path / "file"
        blocker.write_text("not a folder")
        target = blocker / "sub" / "x.bin"  # a path through a regular file fails even for root
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        target = ro / "x.bin"
    with pytest.raises(OutputError, match=str(target.parent.name)):
        atomic_mod.write_bytes_atomic(target, b"data")


def test_error_in_parent_stops_workers_at_once(tmp_path):
    net = hill_net(6, 6)

    class Stop(Exception):
        pass

    def stop(c, done, total):
        raise Stop

    with pytest.raises(Stop):
        bake_lightmap(net, make_lights(), res=8, jobs=2, chunk_size=1, on_chunk=stop)
    deadline = time.monotonic() + 10
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not multiprocessing.active_children()


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        stat = (Path("/proc") / str(pid) / "stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")
def test_workers_die_with_a_killed_parent(tmp_path):
    script = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from lighting_nets import hill_net, make_lights
        from piste.lighting import bake_lightmap

        def slow(c, done, total):
            print("chunk", flush=True)
            time.sleep(30)

        bake_lightmap(hill_net(6, 6), make_lights(), res=8, jobs=2, chunk_size=1, on_chunk=slow)
    """)
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "chunk"
        kids = _children(p.pid)
        assert len(kids) >= 2  # the two workers (and the resource tracker)
    finally:
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
    deadline = time.monotonic() + 10
    while any(_alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = [k for k in kids if _alive(k)]
    for k in left:  # do not leave them behind even if the test fails
        os.kill(k, signal.SIGKILL)
    assert not left, f"{len(left)} of {len(kids)} child processes outlived their killed parent"


def test_full_disk_while_storing_chunks_removes_them(tmp_path, hill, lights, monkeypatch):
    from piste.errors import OutputError

    part = tmp_path / ".partial"
    real = Path.write_bytes
    calls = {"n": 0}

    def filling(self, data):
        calls["n"] += 1
        if calls["n"] > 3:  # the disk fills up after a few chunks
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", filling)
    with pytest.raises(OutputError, match="no space left on the device"):
        bake_lightmap(hill, lights, res=8, chunk_size=1, partial_dir=part)
    monkeypatch.setattr(Path, "write_bytes", real)
    assert [p for p in part.rglob("*") if p.is_file()] == []  # no chunks, no temporary files


def test_stale_partials_of_other_inputs_are_removed(tmp_path, hill, lights):
    part = tmp_path / ".partial"

    class Stop(Exception):
        pass

    def stop(c, done, total):
        raise Stop

    with pytest.raises(Stop):
        bake_lightmap(hill, lights, res=8, chunk_size=1, partial_dir=part, on_chunk=stop)
    (old,) = list(part.iterdir())
    assert list(old.iterdir())  # an abandoned bake's chunk
    bake_lightmap(hill, lights, res=16, chunk_size=1, partial_dir=part)  # other inputs
    assert not old.exists()
