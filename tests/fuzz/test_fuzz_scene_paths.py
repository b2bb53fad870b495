"""Fuzz the paths a scene file names (issue 24 items 1 and 5): every path key of a scene
(``terrain.source`` / ``ssx_pbd`` / ``tiles``, rider and object models, ``ssx:`` models, texture
banks, ``clips_from``, glTF lights files) set to hostile paths built from a folder of traps: ``..``
out of the scene's folder, absolute paths, links to files and folders outside and inside, named
pipes, ``/dev/zero``, folders, NULs, URLs, percent-encodings, names too long for the file system.

Oracle (on top of fuzzlib's: load or a PisteError naming the scene file, under the time and memory
caps): a scene that loads names only regular files (or, for ``tiles``, a folder or nothing yet)
inside the scene's folder, or inside ``outside/`` when the user allowed it (PISTE_ALLOW_PATHS), and
reached through no symbolic link; so do the files it would hash and watch (``source_files``)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from fuzzlib import check, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.formats import safe_io
from piste.world.scene_file import loads_scene

SUFFIXES = [".png", ".npz", ".bpt", ".pbd", ".glb", ".gltf", ".mpf", ".ssh", ".tiles"]
KINDS = {  # path key -> (scene text with {p}, suffixes it takes)
    "terrain.source": ('[terrain]\nsource = {p}\nspacing = 1.0\n', [".png", ".npz", ".bpt"]),
    "terrain.ssx_pbd": ('[terrain]\nssx_pbd = {p}\n', [".pbd"]),
    "terrain.tiles": ('[terrain]\ntiles = {p}\n', [".tiles", ""]),
    "riders.model": ('[[riders]]\nmodel = {p}\nposition = [1.0, 2.0]\n', [".glb", ".gltf"]),
    "riders.model ssx": ('[[riders]]\nmodel = "ssx:" + {p}\nposition = [1.0, 2.0]\n', [".mpf"]),
    "riders.texture": ('[[riders]]\nmodel = "ssx:ok.mpf"\ntexture = {p}\nposition = [1.0, 2.0]\n', [".ssh"]),
    "riders.clips_from": ('[[riders]]\nmodel = "ok.glb"\nclips_from = {p}\nposition = [1.0, 2.0]\n', [".glb"]),
    "objects.model": ('[[objects]]\nmodel = {p}\nposition = [1.0, 2.0]\n', [".gltf", ".glb"]),
    "gltf.file": ('[[gltf]]\nfile = {p}\n', [".gltf", ".glb"]),
}
COMPONENTS = ["ok", "sub", "..", ".", "", "link_out", "link_in", "flink_out", "flink_in", "pipe", "zero", "dir",
              "outside", "secret", "scene", "%2e%2e", "~", "..\\..", "ok\x00", "a" * 300, "sub/deeper", "nope"]


@pytest.fixture(scope="session")
def traps(tmp_path_factory):
    """``root/scene`` (the scene's folder, full of traps) and ``root/outside`` (secrets)."""
    root = tmp_path_factory.mktemp("paths")
    scene, out = root / "scene", root / "outside"
    for d in (scene / "sub" / "deeper", out, scene / "ok.tiles"):
        d.mkdir(parents=True, exist_ok=True)
    for suf in SUFFIXES:
        if suf == ".tiles":
            (out / "secret.tiles").mkdir(exist_ok=True)
            continue
        for f in (scene / f"ok{suf}", scene / "sub" / f"ok{suf}", scene / "sub" / "deeper" / f"ok{suf}"):
            f.write_bytes(b"x")
        (out / f"secret{suf}").write_bytes(b"SECRET")
        os.symlink(out / f"secret{suf}", scene / f"flink_out{suf}")
        os.symlink(f"ok{suf}", scene / f"flink_in{suf}")
        os.symlink("/dev/zero", scene / f"zero{suf}")
        (scene / f"dir{suf}").mkdir()
        if hasattr(os, "mkfifo"):
            os.mkfifo(scene / f"pipe{suf}")
    os.symlink(out, scene / "link_out")
    os.symlink("sub", scene / "link_in")
    return root


def _paths(root: Path):
    """Strategy: a hostile path string and the path key it goes into."""
    plain = st.sampled_from(["ok", "sub/ok", "sub/deeper/ok", "./ok", "sub/../ok", "link_in/ok", "flink_in",
                             "flink_out", "pipe", "zero", "dir", "../outside/secret", "link_out/secret"])
    comp = st.one_of(plain, st.lists(st.sampled_from(COMPONENTS), min_size=0, max_size=5).map("/".join))
    prefix = st.sampled_from(["", "", "", "", "", "", str(root) + "/", str(root / "scene") + "/", str(root / "outside") + "/",
                              "/", "/dev/", "file://", "C:\\", "//", "./"])
    return st.tuples(st.sampled_from(sorted(KINDS)), prefix, comp)


def _no_link_below(base: Path, p: Path) -> bool:
    """``p`` lies below ``base`` and no component from ``base`` down is a symbolic link."""
    rel = os.path.relpath(p, base)
    if rel == ".." or rel.startswith(".." + os.sep) or os.path.isabs(rel):  # ('...tiles' is a name inside)
        return False
    cur = base
    for part in Path(rel).parts:
        cur = cur / part
        if os.path.islink(cur):
            return False
    return True


def _check_confined(scene, allowed: list) -> None:
    """Every path the loaded scene names (and every file it would hash) is inside an allowed
    folder, reached without a link, and a regular file (tiles: a folder or not there yet)."""
    paths = [(scene.terrain.path, "file"), (scene.terrain.tiles, "tiles")]
    paths += [(g.file, "file") for g in scene.gltf]
    for a in scene.riders + scene.objects:
        if a.builtin is None:
            paths.append((a.model, "file"))
        paths += [(a.clips_from, "file"), (a.texture, "file")]
    paths += [(f, "file") for f in scene.source_files() if Path(f) != Path(scene.path).resolve()]
    for p, kind in paths:
        if p is None:
            continue
        p = Path(p)
        base = next((b for b in allowed if _no_link_below(b, p)), None)
        assert base is not None, f"ESCAPE: the scene names {p}, outside {allowed} or through a link"
        if kind == "file":
            assert p.is_file() and not p.is_symlink(), f"the scene names {p}, not a regular file"
            assert p.read_bytes() != b"SECRET" or base.name == "outside", f"ESCAPE: read a secret through {p}"
        else:
            assert not p.exists() or p.is_dir(), f"tiles {p} is not a folder"


@pytest.mark.parametrize("kind", sorted(KINDS))
@given(data=st.data())
@fuzz_settings(8)
def test_scene_paths(traps, kind, data, monkeypatch):
    _, prefix, rel = data.draw(_paths(traps))
    text, sufs = KINDS[kind]
    suf = data.draw(st.sampled_from(sufs + [""]))
    value = prefix + rel + (suf if not rel.endswith("/") else "")
    allow = data.draw(st.booleans())
    scene_dir = traps / "scene"
    allowed = [scene_dir.resolve()] + ([(traps / "outside").resolve()] if allow else [])
    if allow:
        monkeypatch.setenv(safe_io.ALLOW_PATHS_ENV, str(traps / "outside"))
    else:
        monkeypatch.delenv(safe_io.ALLOW_PATHS_ENV, raising=False)
    doc = text.format(p=json.dumps(value)).replace('"ssx:" + "', '"ssx:')

    def load(path):
        scene = loads_scene(doc, path)
        _check_confined(scene, allowed)

    check(load, scene_dir / "scene.toml", f"scene paths {kind}")


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_kind_loads_a_good_path(traps, kind, monkeypatch):
    """The oracle can pass: each kind loads a plain good path (so refusals above are not vacuous)."""
    monkeypatch.delenv(safe_io.ALLOW_PATHS_ENV, raising=False)
    text, sufs = KINDS[kind]
    doc = text.format(p=json.dumps(f"sub/ok{sufs[0]}")).replace('"ssx:" + "', '"ssx:')
    scene = loads_scene(doc, traps / "scene" / "scene.toml")
    _check_confined(scene, [(traps / "scene").resolve()])
