"""The scene file's ``allow_paths`` key reaches the glTF loader (issue 10 item 4): a model whose
buffer lies outside its folder is refused by a scene, and loads when the scene names that folder."""

from __future__ import annotations

import json

import numpy as np
import pytest

from piste.errors import ConfigError, FormatError
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


def _scene(tmp_path, allow=None):
    text = (f"allow_paths = {json.dumps(allow)}\n" if allow is not None else "") + \
        '[[gltf]]\nfile = "models/thing.gltf"\n[[objects]]\nmodel = "models/thing.gltf"\nposition = [1.0, 2.0]\n'
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


def test_scene_allow_paths_allows(layout):
    scene = _scene(layout, ["assets"])
    assert scene.allow_paths == ((layout / "assets").resolve(),)
    assert scene.gltf[0].allow_paths == scene.allow_paths
    import_gltf(scene.gltf[0])
    mesh = load_object_mesh(scene.objects[0].model, allow_paths=scene.allow_paths)
    assert len(mesh.indices) == 1
    assert (layout / "assets" / "tri.bin").resolve() in scene.source_files()


@pytest.mark.parametrize("value, msg", [('"assets"', "expected an array"), ('["nope"]', "is not a folder"),
                                        ("[1]", "expected an array")])
def test_bad_allow_paths(layout, value, msg):
    with pytest.raises(ConfigError, match=msg):
        loads_scene(f"allow_paths = {value}\n", layout / "scene.toml")



def test_build_uses_allow_paths_and_does_not_reuse_a_permitted_step(layout):
    """`piste build` reads the object's buffer only while the scene allows its folder; the cached
    objects step built with the permission is not reused once the permission is gone."""
    from piste.pipeline.build import build_scene

    z = np.add.outer(np.linspace(0, 4, 9), np.linspace(0, 2, 9))
    np.savez(layout / "h.npz", z=z, dx=np.array(10.0))
    body = ('[terrain]\nsource = "h.npz"\n[lightmap]\nres = 4\n[visibility]\nenabled = false\n'
            '[[objects]]\nmodel = "models/thing.gltf"\nposition = [20.0, 20.0]\n')
    (layout / "s.toml").write_text('allow_paths = ["assets"]\n' + body)
    r = build_scene(layout / "s.toml", out=layout / "s.piste", cache_dir=layout / "cache")
    assert r.path.exists()
    (layout / "s.toml").write_text(body)
    with pytest.raises(FormatError, match="leaves the model's folder"):
        build_scene(layout / "s.toml", out=layout / "s2.piste", cache_dir=layout / "cache")
