"""Folders outside a model's own are allowed by the *user* only (issue 24): ``--allow-path DIR`` /
``PISTE_ALLOW_PATHS`` reach the glTF loader through the scene; a scene's own ``allow_paths`` key is
an error (a file never authorises itself)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from piste.errors import ConfigError, FormatError
from piste.formats import safe_io
from piste.pipeline.gltf_import import import_gltf
from piste.pipeline.sources import load_object_mesh
from piste.world.scene_file import loads_scene

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()


def _model(folder, uri):
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": 36}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 0]}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
           "scenes": [{"nodes": [0]}], "scene": 0}
    p = folder / "thing.gltf"
    p.write_text(json.dumps(doc))
    return p


@pytest.fixture
def layout(tmp_path):
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "tri.bin").write_bytes(TRI)
    _model(tmp_path / "models", "../assets/tri.bin")
    return tmp_path


@pytest.fixture(autouse=True)
def _no_user_allow_paths(monkeypatch):
    monkeypatch.delenv(safe_io.ALLOW_PATHS_ENV, raising=False)
    safe_io.set_user_allow_paths(())
    yield
    safe_io.set_user_allow_paths(())


def _scene(tmp_path):
    text = '[[gltf]]\nfile = "models/thing.gltf"\n[[objects]]\nmodel = "models/thing.gltf"\nposition = [1.0, 2.0]\n'
    return loads_scene(text, tmp_path / "scene.toml")


def test_scene_without_allow_paths_refuses(layout):
    scene = _scene(layout)
    assert scene.allow_paths == ()
    with pytest.raises(FormatError, match="leaves the model's folder"):
        import_gltf(scene.gltf[0])
    with pytest.raises(FormatError, match="leaves the model's folder"):
        load_object_mesh(scene.objects[0].model, allow_paths=scene.allow_paths)
    # the refused buffer is neither hashed nor watched
    assert (layout / "assets" / "tri.bin").resolve() not in scene.source_files()


@pytest.mark.parametrize("how", ["flag", "env"])
def test_user_allow_paths_allow(layout, monkeypatch, how):
    if how == "flag":
        safe_io.set_user_allow_paths([layout / "assets"])
    else:
        monkeypatch.setenv(safe_io.ALLOW_PATHS_ENV, str(layout / "assets"))
    scene = _scene(layout)
    assert scene.allow_paths == ((layout / "assets").resolve(),)
    assert scene.gltf[0].allow_paths == scene.allow_paths
    import_gltf(scene.gltf[0])
    mesh = load_object_mesh(scene.objects[0].model)
    assert len(mesh.indices) == 1
    assert (layout / "assets" / "tri.bin").resolve() in scene.source_files()


@pytest.mark.parametrize("value", ['["assets"]', '["/"]', '[]', '"assets"'])
def test_scene_allow_paths_key_is_an_error(layout, value):
    """The key that let a scene switch confinement off for itself (allow_paths = ["/"]) is refused
    by name, whatever it holds, and says what to do instead."""
    with pytest.raises(ConfigError, match=r"key 'allow_paths'.*--allow-path DIR.*PISTE_ALLOW_PATHS"):
        loads_scene(f"allow_paths = {value}\n", layout / "scene.toml")


def test_bad_user_allow_paths(layout, monkeypatch):
    with pytest.raises(ConfigError, match="--allow-path 'nope': not a folder"):
        safe_io.set_user_allow_paths(["nope"])
    monkeypatch.setenv(safe_io.ALLOW_PATHS_ENV, str(layout / "missing"))
    with pytest.raises(ConfigError, match="PISTE_ALLOW_PATHS .*not a folder"):
        safe_io.user_allow_paths()


def test_build_uses_allow_paths_and_does_not_reuse_a_permitted_step(layout):
    """`piste build` reads the object's buffer only while the user allows its folder; the cached
    objects step built with the permission is not reused once the permission is gone."""
    from piste.pipeline.build import build_scene

    z = np.add.outer(np.linspace(0, 4, 9), np.linspace(0, 2, 9))
    np.savez(layout / "h.npz", z=z, dx=np.array(10.0))
    body = ('[terrain]\nsource = "h.npz"\n[lightmap]\nres = 4\n[visibility]\nenabled = false\n'
            '[[objects]]\nmodel = "models/thing.gltf"\nposition = [20.0, 20.0]\n')
    (layout / "s.toml").write_text(body)
    safe_io.set_user_allow_paths([layout / "assets"])
    r = build_scene(layout / "s.toml", out=layout / "s.piste", cache_dir=layout / "cache")
    assert r.path.exists()
    safe_io.set_user_allow_paths(())
    with pytest.raises(FormatError, match="leaves the model's folder"):
        build_scene(layout / "s.toml", out=layout / "s2.piste", cache_dir=layout / "cache")


def test_cli_allow_path_flag(layout, capsys):
    """`piste build SCENE --allow-path DIR`: the only way (with PISTE_ALLOW_PATHS) to let the model
    read ../assets; without it the build stops with one line naming the model and field; a folder
    that does not exist is a usage error; every subcommand takes the flag."""
    from piste.cli import COMMANDS, build_parser, main

    z = np.add.outer(np.linspace(0, 4, 9), np.linspace(0, 2, 9))
    np.savez(layout / "h.npz", z=z, dx=np.array(10.0))
    (layout / "s.toml").write_text('[terrain]\nsource = "h.npz"\n[lightmap]\nres = 4\n[visibility]\nenabled = false\n'
                                   '[[objects]]\nmodel = "models/thing.gltf"\nposition = [20.0, 20.0]\n')
    args = ["build", str(layout / "s.toml"), "--out", str(layout / "s.piste"), "--cache", str(layout / "c"), "--quiet"]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "thing.gltf" in err and "buffers[0].uri" in err and "--allow-path" in err
    assert main(args + ["--allow-path", str(layout / "assets")]) == 0
    assert (layout / "s.piste").exists()
    assert safe_io.user_allow_paths() == ((layout / "assets").resolve(),)
    assert main(args) == 1  # the next run without the flag: nothing allowed
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(args + ["--allow-path", str(layout / "nope")])
    assert e.value.code == 2 and "--allow-path" in capsys.readouterr().err
    parser = build_parser()
    for name in COMMANDS:
        sub = parser._subparsers._group_actions[0].choices[name]
        assert any("--allow-path" in a.option_strings for a in sub._actions), name
