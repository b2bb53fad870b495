"""piste.formats.safe_io (issue 24 item 1): one confinement rule, race-free opens.

Unit tests of the walk (links anywhere below a root refused, special files refused before any read,
the user's allowed folders), a race (a thread swapping a folder of a glTF URI's path for a link to a
folder outside while the model loads in a loop: 0 escapes), and Multitool projects (a FIFO texture,
a linked Textures/ folder)."""

from __future__ import annotations

import json
import os
import threading

import numpy as np
import pytest

from piste.errors import ConfigError, FormatError
from piste.formats import safe_io

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()
SECRET = np.array([[7, 7, 7], [8, 8, 8], [9, 9, 9]], np.float32).tobytes()
needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")


@pytest.fixture(autouse=True)
def _no_user_allow_paths(monkeypatch):
    monkeypatch.delenv(safe_io.ALLOW_PATHS_ENV, raising=False)
    safe_io.set_user_allow_paths(())
    yield
    safe_io.set_user_allow_paths(())


@pytest.fixture
def tree(tmp_path):
    (tmp_path / "m" / "sub").mkdir(parents=True)
    (tmp_path / "m" / "sub" / "a.bin").write_bytes(b"GOOD")
    (tmp_path / "m" / "owner.txt").write_text("x")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "a.bin").write_bytes(b"SECRET")
    return tmp_path


def _read(tree, ref, **kw):
    return safe_io.read_reference(tree / "m" / "owner.txt", ref, 1 << 20, field="f", **kw)


def test_reads_inside(tree):
    assert _read(tree, "sub/a.bin") == b"GOOD"
    assert _read(tree, "./sub/../sub/a.bin") == b"GOOD"


@pytest.mark.parametrize("ref, match", [("../out/a.bin", "leaves the model's folder"),
                                        ("sub/../../out/a.bin", "leaves the model's folder"),
                                        ("ABS", "is an absolute path"), ("file:///etc/passwd", "is a URL"),
                                        ("sub/a.bin\x00x", "NUL"), ("sub", "not a regular file .a folder.")])
def test_refused(tree, ref, match):
    ref = str(tree / "out" / "a.bin") if ref == "ABS" else ref
    with pytest.raises(FormatError, match=match) as ei:
        _read(tree, ref)
    assert ei.value.field == "f" and "owner.txt" in str(ei.value)


def test_links_refused_at_every_component(tree):
    os.symlink(tree / "out" / "a.bin", tree / "m" / "file_link.bin")  # a file link out
    os.symlink(tree / "out", tree / "m" / "dir_link")  # a folder link out
    os.symlink("sub", tree / "m" / "inner_dir")  # links that stay inside: refused too
    os.symlink("a.bin", tree / "m" / "sub" / "inner.bin")
    (tree / "m" / "sub" / "deeper").mkdir()
    os.symlink(tree / "out", tree / "m" / "sub" / "deeper" / "x")
    for ref in ("file_link.bin", "dir_link/a.bin", "inner_dir/a.bin", "sub/inner.bin", "sub/deeper/x/a.bin"):
        with pytest.raises(FormatError, match="symbolic link"):
            _read(tree, ref)
    for fn in (safe_io.check_regular, safe_io.read_regular):
        with pytest.raises(FormatError, match="symbolic link"):
            fn(tree / "m" / "dir_link" / "a.bin", 1 << 20)


def test_users_own_links_above_the_root_are_followed(tree):
    """The folder of a file the user names is trusted as named (links in the user's own path are the
    user's); below it nothing is followed."""
    os.symlink(tree / "m", tree / "alias")
    assert safe_io.read_reference(tree / "alias" / "owner.txt", "sub/a.bin", 100) == b"GOOD"


def test_allowed_folders(tree, monkeypatch):
    with pytest.raises(FormatError, match="leaves"):
        _read(tree, "../out/a.bin")
    assert _read(tree, "../out/a.bin", allow_paths=[tree / "out"]) == b"SECRET"
    safe_io.set_user_allow_paths([tree / "out"])
    assert _read(tree, "../out/a.bin") == b"SECRET"
    assert _read(tree, str(tree / "out" / "a.bin")) == b"SECRET"
    safe_io.set_user_allow_paths(())
    monkeypatch.setenv(safe_io.ALLOW_PATHS_ENV, os.pathsep.join([str(tree / "nothing-here-is-fine"), ""])[:0]
                       + str(tree / "out"))
    assert _read(tree, "../out/a.bin") == b"SECRET"
    with pytest.raises(ConfigError, match="--allow-path"):
        safe_io.set_user_allow_paths([tree / "out" / "a.bin"])


@needs_fifo
def test_fifo_refused_without_blocking(tree):
    os.mkfifo(tree / "m" / "pipe.bin")
    result = {}

    def go():
        for fn in (lambda: _read(tree, "pipe.bin"), lambda: safe_io.read_regular(tree / "m" / "pipe.bin", 100),
                   lambda: safe_io.open_file(tree / "elsewhere-pipe")):
            try:
                fn()
            except FormatError as e:
                result.setdefault("errors", []).append(str(e))

    os.mkfifo(tree / "elsewhere-pipe")
    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():
        for p in (tree / "m" / "pipe.bin", tree / "elsewhere-pipe"):
            os.close(os.open(p, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("a named pipe blocked the reader")
    assert len(result["errors"]) == 3 and all("a named pipe" in e for e in result["errors"])


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_devices_refused_before_reading(tree):
    with pytest.raises(FormatError, match="not a regular file .a device."):
        safe_io.read_regular("/dev/zero", 100)
    with pytest.raises(FormatError, match="not a regular file .a device."):
        _read(tree, "/dev/zero", allow_paths=["/dev"])


def _gltf(folder, uri):
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": 36}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [9, 9, 9]}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
           "scenes": [{"nodes": [0]}], "scene": 0}
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def test_race_swapping_a_folder_for_a_link(tmp_path):
    """A thread swaps the model's ``sub/`` folder for a link to a folder outside (holding a secret
    buffer) while the model loads 1,500 times: no load returns the secret.  A naive open of the
    same path in the same loop does see the secret (the race is real)."""
    from piste.formats.gltf import load_gltf

    model, out = tmp_path / "model", tmp_path / "outside"
    (model / "sub").mkdir(parents=True)
    out.mkdir()
    (model / "sub" / "b.bin").write_bytes(TRI)
    (out / "b.bin").write_bytes(SECRET)
    path = _gltf(model, "sub/b.bin")
    stop = threading.Event()

    def swap():
        while not stop.is_set():
            os.rename(model / "sub", model / "sub_real")
            os.symlink(out, model / "sub")
            os.unlink(model / "sub")
            os.rename(model / "sub_real", model / "sub")

    assert load_gltf(path).meshes[0].positions.max() <= 1  # without the race
    t = threading.Thread(target=swap, daemon=True)
    t.start()
    escapes = good = refused = naive_escapes = 0
    try:
        for _ in range(1500):
            try:
                pos = load_gltf(path).meshes[0].positions
                if pos.max() > 5:
                    escapes += 1
                else:
                    good += 1
            except FormatError:
                refused += 1
            try:
                with open(model / "sub" / "b.bin", "rb") as fh:
                    naive_escapes += fh.read() == SECRET
            except OSError:
                pass
    finally:
        stop.set()
        t.join(5)
    assert escapes == 0, f"{escapes} of 1500 loads read outside the model's folder ({good} read its own)"
    if naive_escapes == 0:  # the swapper never won a naive open: the race was not exercised
        pytest.skip("the swapping thread never interleaved (no naive escape seen)")


# ------------------------------------------------------------------------------ Multitool projects
def _project(folder):
    """A one-patch Multitool project with its texture ``Textures/0000.png``."""
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    p = {"PatchName": "p", "Points": [[float(i % 4), float(i // 4), 0.0] for i in range(16)],
         "UVPoints": [[0, 0], [1, 0], [1, 1], [0, 1]], "LightMapPoint": [0, 0, 0.1, 0.1],
         "LightmapID": 0, "SurfaceType": 1, "TrickOnlyPatch": False, "TexturePath": "0000.png"}
    (folder / "Patches.json").write_text(json.dumps({"Patches": [p]}))
    (folder / "Textures").mkdir()
    Image.fromarray(np.full((8, 8, 4), 200, np.uint8)).save(folder / "Textures" / "0000.png")
    return folder


def test_multitool_project_reads(tmp_path):
    from piste.formats.ssx.multitool import read_project

    proj = read_project(_project(tmp_path / "p"))
    assert list(proj.textures) == [0]


@needs_fifo
def test_multitool_fifo_texture_refused_without_blocking(tmp_path):
    from piste.formats.ssx.multitool import read_project

    folder = _project(tmp_path / "p")
    (folder / "Textures" / "0000.png").unlink()
    os.mkfifo(folder / "Textures" / "0000.png")
    result = {}

    def go():
        try:
            read_project(folder)
        except FormatError as e:
            result["e"] = e

    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():
        os.close(os.open(folder / "Textures" / "0000.png", os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("piste ssx import blocked on a named pipe at Textures/0000.png")
    assert "0000.png" in str(result["e"]) and "a named pipe" in str(result["e"])


def test_multitool_linked_textures_folder_not_followed(tmp_path):
    from piste.formats.ssx.multitool import read_project

    folder = _project(tmp_path / "p")
    other = _project(tmp_path / "elsewhere")
    import shutil

    shutil.rmtree(folder / "Textures")
    os.symlink(other / "Textures", folder / "Textures")
    with pytest.raises(FormatError, match="symbolic link"):
        read_project(folder)


# ------------------------------------------------------------------------------ SSX partner files
def test_ssx_level_partner_files_are_not_followed_through_links(tmp_path):
    """A level named by the user: its folder is a confinement root, so LEVEL.ssh beside it (found
    by name, not by a path in the file) is refused when it is a link out, and read when it is a file."""
    from piste.pipeline.ssx_synth import make_level
    from piste.formats.ssx.pbd import write_pbd
    from piste.formats.ssx.ssh import write_ssh
    from piste.pipeline.ssx_level import load_level

    lvl = make_level(rows=2, cols=2, seed=3)
    (tmp_path / "lv").mkdir()
    (tmp_path / "out").mkdir()
    write_pbd(lvl.pbd, tmp_path / "lv" / "level.pbd")
    write_ssh(lvl.textures, tmp_path / "out" / "level.ssh")
    os.symlink(tmp_path / "out" / "level.ssh", tmp_path / "lv" / "level.ssh")
    with pytest.raises(FormatError, match="symbolic link") as e:
        load_level(tmp_path / "lv" / "level.pbd")
    assert "level.ssh" in str(e.value)
    os.unlink(tmp_path / "lv" / "level.ssh")
    write_ssh(lvl.textures, tmp_path / "lv" / "level.ssh")
    assert load_level(tmp_path / "lv" / "level.pbd").net is not None


@needs_fifo
@pytest.mark.parametrize("reader", ["bundle", "net", "gltf", "scene"])
def test_top_level_files_named_by_the_user_refuse_fifos(tmp_path, reader):
    """The files a user names directly (a bundle, a saved net, a model, a scene) go through the same
    opener: a named pipe is refused at once (it used to block zipfile / np.load / open)."""
    from piste.formats.bundle import read_bundle
    from piste.formats.gltf import load_gltf
    from piste.terrain.net import PatchNet
    from piste.world.scene_file import load_scene

    fn, name = {"bundle": (read_bundle, "x.piste"), "net": (PatchNet.load, "x.npz"),
                "gltf": (load_gltf, "x.gltf"), "scene": (load_scene, "x.toml")}[reader]
    os.mkfifo(tmp_path / name)
    result = {}

    def go():
        try:
            fn(tmp_path / name)
        except Exception as e:  # reported below
            result["e"] = e

    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():
        os.close(os.open(tmp_path / name, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail(f"{reader}: blocked on a named pipe")
    from piste.errors import PisteError

    assert isinstance(result["e"], PisteError) and name in str(result["e"]), result["e"]
    assert "pipe" in str(result["e"]) or "not a regular file" in str(result["e"])
