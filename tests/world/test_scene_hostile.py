"""Hostile scene and light TOML files (issue 10 item 3): deep nesting refused before tomllib
recurses, special files (pipes) refused before reading."""

from __future__ import annotations

import os

import pytest

from piste.errors import ConfigError
from piste.world.scene_file import loads_scene


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_terrain_source_fifo_refused(tmp_path):
    os.mkfifo(tmp_path / "h.png")
    with pytest.raises(ConfigError, match="not a regular file"):
        loads_scene('[terrain]\nsource = "h.png"\n', tmp_path / "scene.toml")


def test_deeply_nested_scene_and_lights_toml(tmp_path):
    from piste.errors import FormatError
    from piste.lighting import loads_lights

    deep = "x = " + "[" * 5000 + "]" * 5000 + "\n"
    with pytest.raises(ConfigError, match=r"s\.toml: arrays or tables nested more than 32 deep"):
        loads_scene(deep, tmp_path / "s.toml")
    with pytest.raises(FormatError, match=r"l\.toml: arrays or tables nested more than 32 deep"):
        loads_lights(deep, tmp_path / "l.toml")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_scene_file_fifo_refused(tmp_path):
    from piste.world.scene_file import load_scene

    os.mkfifo(tmp_path / "s.toml")
    with pytest.raises(ConfigError, match="not a regular file"):
        load_scene(tmp_path / "s.toml")


def test_path_too_long_for_the_file_system(tmp_path):
    text = '[[objects]]\nmodel = "' + "a" * 10000 + '"\nposition = [1.0, 2.0]\n'
    with pytest.raises(ConfigError, match=r"s\.toml, line 2, key 'objects\[0\]\.model': cannot use the path"):
        loads_scene(text, tmp_path / "s.toml")


def test_huge_toml_refused_before_parsing(tmp_path):
    from piste.errors import FormatError
    from piste.lighting import loads_lights

    text = 'name = "' + "a" * (17 << 20) + '"\n'
    with pytest.raises(ConfigError, match=r"s\.toml: .* more than the limit"):
        loads_scene(text, tmp_path / "s.toml")
    with pytest.raises(FormatError, match=r"l\.toml: .* more than the limit"):
        loads_lights(text, tmp_path / "l.toml")


# ------------------------------------------------------------------------------ confinement (issue 24)
# Every kind of path a scene names, as (scene text with {p} for the path, the key named in the
# error, the suffix a file of that kind has).  Each must resolve inside the scene's folder (or a
# folder the user allows), through no symbolic link, to a regular file.
PATH_KINDS = {
    "terrain.source (height field)": ('[terrain]\nsource = "{p}"\nspacing = 1.0\n', "terrain.source", ".png"),
    "terrain.source (.bpt)": ('[terrain]\nsource = "{p}"\n', "terrain.source", ".bpt"),
    "terrain.ssx_pbd": ('[terrain]\nssx_pbd = "{p}"\n', "terrain.ssx_pbd", ".pbd"),
    "riders.model": ('[[riders]]\nmodel = "{p}"\nposition = [1.0, 2.0]\n', "riders[0].model", ".glb"),
    "riders.model (ssx:)": ('[[riders]]\nmodel = "ssx:{p}"\nposition = [1.0, 2.0]\n', "riders[0].model", ".mpf"),
    "riders.texture": ('[[riders]]\nmodel = "ssx:ok.mpf"\ntexture = "{p}"\nposition = [1.0, 2.0]\n',
                       "riders[0].texture", ".ssh"),
    "riders.clips_from": ('[[riders]]\nmodel = "ok.glb"\nclips_from = "{p}"\nposition = [1.0, 2.0]\n',
                          "riders[0].clips_from", ".glb"),
    "objects.model": ('[[objects]]\nmodel = "{p}"\nposition = [1.0, 2.0]\n', "objects[0].model", ".gltf"),
    "gltf.file (lights)": ('[[gltf]]\nfile = "{p}"\n', "gltf[0].file", ".gltf"),
    "terrain.tiles (a folder)": ('[terrain]\ntiles = "{p}"\n', "terrain.tiles", ".tiles"),
}


@pytest.fixture
def tree(tmp_path):
    """``scene/`` (the scene's folder, with good files ok.mpf and ok.glb) and ``outside/`` (a
    secret of every kind beside it)."""
    scene, out = tmp_path / "scene", tmp_path / "outside"
    scene.mkdir()
    out.mkdir()
    (scene / "ok.mpf").write_bytes(b"x")
    (scene / "ok.glb").write_bytes(b"x")
    for _, _, suf in PATH_KINDS.values():
        (out / f"secret{suf}").write_bytes(b"SECRET") if suf != ".tiles" else (out / "secret.tiles").mkdir(exist_ok=True)
    return scene, out


def _refused(scene_dir, kind, p, match):
    text, key, _ = PATH_KINDS[kind]
    with pytest.raises(ConfigError, match=match) as ei:
        loads_scene(text.format(p=p), scene_dir / "scene.toml")
    assert f"key '{key}'" in str(ei.value), str(ei.value)
    assert "SECRET" not in str(ei.value)


@pytest.mark.parametrize("kind", PATH_KINDS)
def test_dotdot_escape_refused(tree, kind):
    scene, out = tree
    suf = PATH_KINDS[kind][2]
    _refused(scene, kind, f"../outside/secret{suf}", "leaves the scene's folder")
    _refused(scene, kind, f"sub/../../outside/secret{suf}", "leaves the scene's folder")


@pytest.mark.parametrize("kind", PATH_KINDS)
def test_absolute_path_refused(tree, kind):
    scene, out = tree
    _refused(scene, kind, str(out / f"secret{PATH_KINDS[kind][2]}"), "is an absolute path")


@pytest.mark.parametrize("kind", PATH_KINDS)
def test_symlinked_file_refused(tree, kind):
    """A link to a file outside, and a link to a file inside: neither is followed."""
    scene, out = tree
    suf = PATH_KINDS[kind][2]
    os.symlink(out / f"secret{suf}", scene / f"link{suf}")
    _refused(scene, kind, f"link{suf}", "symbolic link")
    if suf != ".tiles":
        (scene / f"real{suf}").write_bytes(b"x")
        os.symlink(f"real{suf}", scene / f"inner{suf}")
        _refused(scene, kind, f"inner{suf}", "symbolic link")


@pytest.mark.parametrize("kind", PATH_KINDS)
def test_symlinked_folder_refused(tree, kind):
    scene, out = tree
    os.symlink(out, scene / "assets")
    _refused(scene, kind, f"assets/secret{PATH_KINDS[kind][2]}", "symbolic link")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
@pytest.mark.parametrize("kind", [k for k in PATH_KINDS if "tiles" not in k])
def test_fifo_refused_without_hanging(tree, kind):
    import threading

    scene, _ = tree
    suf = PATH_KINDS[kind][2]
    os.mkfifo(scene / f"pipe{suf}")
    result = {}

    def go():
        try:
            _refused(scene, kind, f"pipe{suf}", "not a regular file")
            result["ok"] = True
        except BaseException as exc:  # reported below, in the test's thread
            result["exc"] = exc

    t = threading.Thread(target=go, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():  # unblock the reader so the process can exit, then fail
        os.close(os.open(scene / f"pipe{suf}", os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail(f"{kind}: the scene loader blocked on a named pipe")
    if "exc" in result:
        raise result["exc"]


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
@pytest.mark.parametrize("kind", [k for k in PATH_KINDS if "tiles" not in k])
def test_dev_zero_refused(tree, kind, monkeypatch):
    from piste.formats import safe_io

    scene, _ = tree
    _refused(scene, kind, "/dev/zero", "is an absolute path")
    monkeypatch.setenv(safe_io.ALLOW_PATHS_ENV, "/dev")  # even where the user allows /dev: not a regular file
    _refused(scene, kind, "/dev/zero", "not a regular file")


def test_allowed_folder_reads_and_key_cannot_allow(tree, monkeypatch):
    """The user's PISTE_ALLOW_PATHS lets a scene name a file outside; the scene's own key cannot."""
    from piste.formats import safe_io

    scene, out = tree
    text = '[[gltf]]\nfile = "../outside/secret.gltf"\n'
    with pytest.raises(ConfigError, match="leaves the scene's folder"):
        loads_scene(text, scene / "scene.toml")
    with pytest.raises(ConfigError, match="key 'allow_paths'"):
        loads_scene('allow_paths = ["/"]\n' + text, scene / "scene.toml")
    monkeypatch.setenv(safe_io.ALLOW_PATHS_ENV, str(out))
    s = loads_scene(text, scene / "scene.toml")
    assert s.gltf[0].file == (out / "secret.gltf").resolve()


@pytest.mark.parametrize("uri", ["../outside/secret.gltf", "ABSOLUTE", "link/secret.gltf", "pipe.bin"])
def test_gltf_uri_of_a_scene_model_confined(tree, uri):
    """The 11th kind: a URI inside a model the scene names is confined to the model's folder."""
    import json

    from piste.errors import FormatError
    from piste.pipeline.sources import load_object_mesh

    scene, out = tree
    (scene / "m").mkdir()
    os.symlink(out, scene / "m" / "link")
    if hasattr(os, "mkfifo"):
        os.mkfifo(scene / "m" / "pipe.bin")
    uri = str(out / "secret.gltf") if uri == "ABSOLUTE" else uri
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": 36}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 0]}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
           "scenes": [{"nodes": [0]}], "scene": 0}
    (scene / "m" / "t.gltf").write_text(json.dumps(doc))
    s = loads_scene('[[objects]]\nmodel = "m/t.gltf"\nposition = [1.0, 2.0]\n', scene / "scene.toml")
    with pytest.raises(FormatError, match="leaves the model's folder|absolute path|symbolic link|not a regular") as ei:
        load_object_mesh(s.objects[0].model)
    assert "buffers[0].uri" in str(ei.value)


def test_race_swapping_a_scene_folder_for_a_link(tmp_path):
    """A thread swaps the scene's ``models/`` folder for a link to a folder outside holding a model
    of the same name (whose triangle is the secret) while the scene is loaded and its object read
    600 times: no read returns the outside model (each open walks from the scene's folder)."""
    import json
    import threading

    import numpy as np

    from piste.errors import PisteError
    from piste.pipeline.sources import load_object_mesh

    def model(folder, tri):
        folder.mkdir(parents=True)
        (folder / "tri.bin").write_bytes(np.asarray(tri, np.float32).tobytes())
        doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "tri.bin", "byteLength": 36}],
               "bufferViews": [{"buffer": 0, "byteLength": 36}],
               "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                              "min": [0, 0, 0], "max": [9, 9, 9]}],
               "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
               "scenes": [{"nodes": [0]}], "scene": 0}
        (folder / "thing.gltf").write_text(json.dumps(doc))

    scene, out = tmp_path / "scene", tmp_path / "outside"
    model(scene / "models", [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    model(out, [[7, 7, 7], [8, 8, 8], [9, 9, 9]])
    text = '[[objects]]\nmodel = "models/thing.gltf"\nposition = [1.0, 2.0]\n'
    stop = threading.Event()

    swaps = []

    def swap():
        import time

        while not stop.is_set():  # each state held a moment, so that loads meet both
            os.rename(scene / "models", scene / "models_real")
            os.symlink(out, scene / "models")
            time.sleep(0.0003)
            os.unlink(scene / "models")
            os.rename(scene / "models_real", scene / "models")
            swaps.append(1)
            time.sleep(0.0003)

    clean = load_object_mesh(loads_scene(text, scene / "scene.toml").objects[0].model)  # without the race
    assert np.abs(clean.positions).max() <= 1
    t = threading.Thread(target=swap, daemon=True)
    t.start()
    escapes = good = naive = 0
    secret = np.asarray([[7, 7, 7], [8, 8, 8], [9, 9, 9]], np.float32).tobytes()
    try:
        for _ in range(600):
            try:  # a naive open of the same path, to show the race is exercised
                with open(scene / "models" / "tri.bin", "rb") as fh:
                    naive += fh.read() == secret
            except OSError:
                pass
            try:
                s = loads_scene(text, scene / "scene.toml")
                mesh = load_object_mesh(s.objects[0].model)
            except PisteError:
                continue
            if np.abs(mesh.positions).max() > 5:
                escapes += 1
            else:
                good += 1
    finally:
        stop.set()
        t.join(5)
    assert escapes == 0, f"{escapes} of 600 loads read the model outside the scene's folder ({good} read its own)"
    if naive == 0:
        pytest.skip(f"the swapping thread never interleaved (no naive escape seen; {len(swaps)} swaps, "
                    f"{good} good loads)")
