"""glTF fields pygltflib passes through unchecked (issue 10 items 3, 6): lights, cameras, morph
weights and nodes scaled to zero give a model or a FormatError naming the field, never a raw error."""

from __future__ import annotations

import base64
import copy
import json

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats import load_gltf

POS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
DELTA = np.array([[0, 0, 1]] * 3, np.float32)
NRM = np.array([[0, 0, 1]] * 3, np.float32)
BLOB = POS.tobytes() + DELTA.tobytes() + NRM.tobytes()


def base_doc():
    return {
        "asset": {"version": "2.0"},
        "buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(BLOB).decode(),
                     "byteLength": len(BLOB)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 72, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 1], "max": [0, 0, 1]},
                      {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 2}, "targets": [{"POSITION": 1}]}]}],
        "nodes": [{"mesh": 0, "name": "tri"},
                  {"name": "lamp", "translation": [0, 5, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
                  {"name": "cam", "translation": [0, 1, 9], "camera": 0}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1, "zfar": 100}}],
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "spot", "color": [1, 0.5, 0.2], "intensity": 20,
                                                          "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.5}}]}},
        "scenes": [{"nodes": [0, 1, 2]}],
        "scene": 0,
    }


def _load(tmp_path, doc, name="m.gltf"):
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return load_gltf(p)


def test_valid_document_loads(tmp_path):
    m = _load(tmp_path, base_doc())
    from piste.scene_data import Camera, SpotLight

    # lights and cameras come as piste's own (scene_data), placed Z up: glTF (0, 5, 0) is piste (0, 0, 5)
    assert len(m.lights) == 1 and isinstance(m.lights[0], SpotLight) and m.lights[0].position == (0.0, 0.0, 5.0)
    assert m.lights[0].outer_angle == pytest.approx(np.degrees(0.5))
    assert len(m.cameras) == 1 and isinstance(m.cameras[0], Camera) and m.cameras[0].fov_y == pytest.approx(np.degrees(0.8))
    assert m.cameras[0].name == "cam" and m.cameras[0].near == pytest.approx(0.1) and m.cameras[0].far == pytest.approx(100)


def test_morph_targets_without_mesh_weights_load_with_zero_weights(tmp_path):
    m = _load(tmp_path, base_doc())  # the base document has targets and no mesh.weights
    assert m.meshes[0].morph_default_weights.tolist() == [0.0]
    d = base_doc()
    d["meshes"][0]["weights"] = [0.25]
    assert _load(tmp_path, d, "w.gltf").meshes[0].morph_default_weights.tolist() == [0.25]


def _set(doc, path, value):
    o = doc
    for k in path[:-1]:
        o = o[k]
    o[path[-1]] = value


L = ("extensions", "KHR_lights_punctual", "lights", 0)
P = ("cameras", 0, "perspective")


@pytest.mark.parametrize("path, value, field", [
    (L + ("color",), "red", "lights[0].color"),
    (L + ("color",), [1, 1], "lights[0].color"),
    (L + ("color",), [1, None, 1], "lights[0].color"),
    (L + ("intensity",), "bright", "lights[0].intensity"),
    (L + ("intensity",), 1e308, "lights[0].intensity"),
    (L + ("intensity",), -1, "lights[0].intensity"),
    (L + ("type",), "laser", "lights[0].type"),
    (L + ("range",), 0, "lights[0].range"),
    (L + ("spot",), "wide", "lights[0].spot"),
    (L + ("spot", "outerConeAngle"), "wide", "outerConeAngle"),
    (L + ("spot", "innerConeAngle"), 0.9, "lights[0].spot"),
    (("extensions", "KHR_lights_punctual", "lights", 0), "a light", "lights[0]"),
    (("extensions", "KHR_lights_punctual", "lights"), {"a": 1}, "KHR_lights_punctual.lights"),
    (P + ("yfov",), None, "perspective.yfov"),
    (P + ("yfov",), 4.0, "perspective.yfov"),
    (P + ("znear",), 0, "perspective.znear"),
    (P + ("zfar",), 0.01, "perspective.zfar"),
    (P + ("aspectRatio",), -1, "perspective.aspectRatio"),
    (("meshes", 0, "weights"), ["a"], "meshes[0].weights"),  # (pygltflib's parse used to reject it first)
    (("meshes", 0, "weights"), [0.1, 0.2], "meshes[0].weights"),
    (("meshes", 0, "weights"), [float("nan")], "meshes[0].weights"),
])
def test_bad_field_is_a_format_error_naming_it(tmp_path, path, value, field):
    d = base_doc()
    _set(d, path, value)
    p = tmp_path / "bad.gltf"
    p.write_text(json.dumps(d, allow_nan=True))
    with pytest.raises(FormatError) as ei:
        load_gltf(p)
    msg = str(ei.value)
    assert "bad.gltf" in msg and field in msg, msg


@pytest.mark.parametrize("how", ["scale", "matrix"])
def test_node_scaled_to_zero_loads(tmp_path, how):
    d = base_doc()
    if how == "scale":
        d["nodes"][0]["scale"] = [0, 0, 0]
    else:
        d["nodes"][0]["matrix"] = [0] * 15 + [1]
    m = _load(tmp_path, d)
    assert np.isfinite(m.meshes[0].positions).all() and np.isfinite(m.meshes[0].normals).all()
    assert np.abs(m.meshes[0].positions).max() == 0  # collapsed to the node's origin


def test_zero_scale_animated_node_keeps_its_shape(tmp_path):
    """A node scaled to 0 at rest and animated to 1 (an "appear" animation) still skins to its shape."""
    d = base_doc()
    d["nodes"][0]["scale"] = [0, 0, 0]
    times = np.array([0, 1], np.float32).tobytes()
    scales = np.array([[0, 0, 0], [1, 1, 1]], np.float32).tobytes()
    blob = BLOB + times + scales
    d["buffers"][0] = {"uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
                       "byteLength": len(blob)}
    d["bufferViews"] += [{"buffer": 0, "byteOffset": 108, "byteLength": 8}, {"buffer": 0, "byteOffset": 116, "byteLength": 24}]
    d["accessors"] += [{"bufferView": 3, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
                       {"bufferView": 4, "componentType": 5126, "count": 2, "type": "VEC3"}]
    d["animations"] = [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "scale"}}],
                        "samplers": [{"input": 3, "output": 4}]}]
    m = _load(tmp_path, d)
    assert m.skeleton is not None
    mesh = m.meshes[0]
    pose = m.clips["animation0"].sample(1.0, m.skeleton)
    skin = m.skeleton.skin_matrices(pose)  # (bones, 4, 4) world @ inverse bind
    b = mesh.joints[:, 0]
    out = np.einsum("vij,vj->vi", skin[b][:, :3, :3], mesh.positions.astype(np.float64)) + skin[b][:, :3, 3]
    np.testing.assert_allclose(out, POS, atol=1e-6)
    rest = m.skeleton.skin_matrices(m.clips["animation0"].sample(0.0, m.skeleton))
    out0 = np.einsum("vij,vj->vi", rest[b][:, :3, :3], mesh.positions.astype(np.float64)) + rest[b][:, :3, 3]
    np.testing.assert_allclose(out0, 0.0, atol=1e-6)
