"""glTF import: every real test model, an independent skinning check, synthetic features, malformed files."""

from __future__ import annotations

import base64
import json
import os
import shutil
import struct
from pathlib import Path

import numpy as np
import pygltflib
import pytest

import piste.formats
from piste.character import Model
from piste.formats import load_gltf
from piste.errors import FormatError, PisteError

DATA = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
GLTF_FILES = sorted(p for p in (DATA / "gltf").glob("*/*") if p.suffix in (".gltf", ".glb"))

# From MANIFEST.md: folder -> (joints per skin, vertices, triangles, morph targets per prim, animations)
MANIFEST = {
    "CesiumMan": ([19], 3273, 4672, [], {"animation0": 2.0}),
    "RiggedFigure": ([19], 370, 256, [], {"animation0": 1.25}),
    "RiggedSimple": ([2], 96, 188, [], {"animation0": 2.083}),
    "AnimatedMorphCube": ([], 24, 12, [2], {"Square": 4.2}),
    "SimpleMorph": ([], 3, 1, [2], {"animation0": 4.0}),
    "SimpleSkin": ([2], 10, 8, [], {"animation0": 5.5}),
    "Fox": ([24], 1728, 576, [], {"Survey": 3.417, "Walk": 0.708, "Run": 1.158}),
    "MorphPrimitivesTest": ([], 30, 32, [1, 1], {}),
    "Girl": ([23], 496, 561, [], {"IdleTrack": 1.667, "RunTrack": 1.0}),
    "RobotExpressive": ([43] * 4, 7214, 3237, [3, 3, 3],
                        {n: None for n in ("Dance", "Death", "Idle", "Jump", "No", "Punch", "Running", "Sitting",
                                           "Standing", "ThumbsUp", "Walking", "WalkJump", "Wave", "Yes")}),
}


def _file(folder):
    return next(p for p in GLTF_FILES if p.parent.name == folder)


needs_data = pytest.mark.skipif(not GLTF_FILES, reason="test models not present")


# ----------------------------------------------------------------------------------------------
@needs_data
@pytest.mark.parametrize("folder", sorted(MANIFEST))
def test_every_model_loads_with_manifest_counts(folder, gltf_model):
    m = gltf_model(folder)
    joints, nv, nt, morphs, anims = MANIFEST[folder]
    assert isinstance(m, Model)
    assert m.n_vertices == nv
    assert m.n_triangles == nt
    assert sorted(m.clips) == sorted(anims)
    for name, dur in anims.items():
        if dur is not None:
            assert m.clips[name].duration == pytest.approx(dur, abs=1e-3)
    assert sorted(mm.n_morphs for mm in m.meshes if mm.n_morphs) == sorted(morphs)
    if joints:
        sk = m.skeleton
        assert sk is not None and int(sk.is_joint.sum()) == joints[0]
        assert np.all(sk.parents < np.arange(sk.n_bones))
        assert all(mm.skinned for mm in m.meshes)
    for mm in m.meshes:
        v = mm.n_vertices
        assert mm.positions.shape == (v, 3) and mm.positions.dtype == np.float32
        assert mm.normals.shape == (v, 3) and mm.uv.shape == (v, 2)
        assert mm.indices.dtype == np.uint32 and mm.indices.max() < v
        assert np.allclose(np.linalg.norm(mm.normals, axis=1), 1.0, atol=1e-3)
        assert mm.joints.dtype == np.uint16 and mm.weights.dtype == np.float32
        assert np.allclose(mm.weights.sum(1), 1.0, atol=1e-5)
        assert np.all(mm.weights >= 0)
        if m.skeleton is not None:
            assert mm.joints.max() < m.skeleton.n_bones
        assert mm.morph_positions.shape == (mm.n_morphs, v, 3)
        assert np.all(np.isfinite(mm.positions))


@needs_data
def test_reexports():
    assert piste.formats.load_gltf is load_gltf


def _node_world(g):
    """Independent rest world matrices of glTF nodes (recursive, straight from the JSON)."""
    parent = {c: i for i, n in enumerate(g.nodes) for c in (n.children or [])}

    def local(n):
        if n.matrix:
            return np.array(n.matrix, dtype=float).reshape(4, 4).T
        x, y, z, w = n.rotation or [0, 0, 0, 1.0]
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        m = np.eye(4)
        m[:3, :3] = r * np.array(n.scale or [1, 1, 1.0])
        m[:3, 3] = n.translation or [0, 0, 0]
        return m

    def world(i):
        return local(g.nodes[i]) if i not in parent else world(parent[i]) @ local(g.nodes[i])

    return world


@needs_data
@pytest.mark.parametrize("folder", ["CesiumMan", "RiggedFigure", "RiggedSimple", "Fox"])
def test_skin_matrices_at_rest_equal_mesh_node_world(folder, gltf_model):
    """For models whose rest pose is the bind pose, skinning at rest must place the mesh exactly as
    its node's world transform would (independent node-world computation from the raw JSON)."""
    m = gltf_model(folder)
    sk = m.skeleton
    g = pygltflib.GLTF2().load(str(_file(folder)))
    world = _node_world(g)
    mesh_node = next(i for i, n in enumerate(g.nodes) if n.skin is not None)
    skin = g.skins[g.nodes[mesh_node].skin]
    bones = [int(np.flatnonzero(sk.node_index == j)[0]) for j in skin.joints]
    s = sk.skin_matrices(sk.rest_pose())[bones]
    assert np.allclose(s, world(mesh_node), atol=1e-4)
    # and the inverse bind matrices are the raw accessor data
    assert np.allclose(sk.world_matrices()[bones] @ sk.inverse_bind[bones], world(mesh_node), atol=1e-4)


@needs_data
def test_cesium_man_skinned_rest_is_upright_person(gltf_model):
    m = gltf_model("CesiumMan")
    mesh = m.meshes[0]
    s = m.skeleton.skin_matrices()
    p = np.einsum("vk,vkij,vj->vi", mesh.weights, s[mesh.joints][..., :3, :3], mesh.positions) + np.einsum(
        "vk,vki->vi", mesh.weights, s[mesh.joints][..., :3, 3])
    ext = p.max(0) - p.min(0)
    assert ext[1] == pytest.approx(1.5, abs=0.1)  # about 1.5 m tall, Y up after the Z_UP node
    assert ext[1] > 2 * ext[0] and ext[1] > 2 * ext[2] * 0.5


@needs_data
def test_textures_and_materials(gltf_model):
    cm = gltf_model("CesiumMan")
    assert cm.meshes[0].texture.shape == (1024, 1024, 4) and cm.meshes[0].texture.dtype == np.uint8
    mp = gltf_model("MorphPrimitivesTest")  # external .jpg image
    assert mp.meshes[0].texture is not None and mp.meshes[0].texture.shape[2] == 4
    assert gltf_model("RiggedSimple").meshes[0].texture is None
    robot = gltf_model("RobotExpressive")
    colors = {tuple(np.round(mm.base_color, 3)) for mm in robot.meshes}
    assert len(colors) >= 2


@needs_data
def test_morph_names_and_defaults(gltf_model):
    robot = gltf_model("RobotExpressive")
    face = [mm for mm in robot.meshes if mm.n_morphs]
    assert len(face) == 3
    assert all(mm.morph_names == ["Angry", "Surprised", "Sad"] for mm in face)
    sm = gltf_model("SimpleMorph")
    assert np.allclose(sm.meshes[0].morph_default_weights, [0.5, 0.5])
    assert sm.meshes[0].morph_positions.any()
    cube = gltf_model("AnimatedMorphCube")
    assert cube.meshes[0].morph_normals.any()


@needs_data
def test_robot_rigid_parts_follow_their_bones(gltf_model):
    robot = gltf_model("RobotExpressive")
    sk = robot.skeleton
    rigid = [mm for mm in robot.meshes if np.all(mm.weights[:, 0] == 1) and len(np.unique(mm.joints[:, 0])) == 1]
    assert len(rigid) >= 10
    # non-joint bones carry inverse(rest world): identity skin matrices at rest
    s = sk.skin_matrices()
    for mm in rigid:
        b = mm.joints[0, 0]
        if not sk.is_joint[b]:
            assert np.allclose(s[b], np.eye(4), atol=1e-6)


@needs_data
def test_weight_tracks_and_clip_skeleton(gltf_model):
    robot = gltf_model("RobotExpressive")
    face = next(mm for mm in robot.meshes if mm.n_morphs)
    w = robot.clips["Dance"].sample_weights(1.0, face)
    assert w.shape == (3,)
    cube = gltf_model("AnimatedMorphCube")
    clip = cube.clips["Square"]
    ws = np.array([clip.sample_weights(t, "Cube") for t in np.linspace(0, clip.duration, 30)])
    assert ws.max() > 0.5 and ws.min() >= -1e-6
    assert np.allclose(clip.sample_weights(1.0, 0), clip.sample_weights(1.0, "Cube"))


# ---------------------------------------------------------------------------------------------- synthetic files
def _pack(arrays):
    """Concatenate arrays (4-byte aligned); returns bytes and list of (offset, length)."""
    blob = b""
    views = []
    for a in arrays:
        b = np.ascontiguousarray(a).tobytes()
        pad = (-len(blob)) % 4
        blob += b"\0" * pad
        views.append((len(blob), len(b)))
        blob += b
    return blob, views


def _synthetic(tmp_path, interpolation="LINEAR", sparse=False, weights_u8=False, extra=None):
    """A 2-bone skinned quad, a rigid child mesh, a light and a camera, written as .gltf with an
    embedded data-URI buffer."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 2, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    joints = np.array([[0, 1, 0, 0]] * 4, np.uint8)
    if weights_u8:
        weights = np.array([[255, 0, 0, 0], [255, 0, 0, 0], [128, 127, 0, 0], [0, 255, 0, 0]], np.uint8)
    else:
        weights = np.array([[1, 0, 0, 0], [1, 0, 0, 0], [0.5, 0.5, 0, 0], [0, 1, 0, 0]], np.float32)
    ibm = np.stack([np.eye(4), np.linalg.inv(np.array([[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]]))])
    ibm = ibm.transpose(0, 2, 1).astype(np.float32)  # column-major
    times = np.array([0.0, 1.0, 2.0], np.float32)
    s = np.sin(np.pi / 4)
    rots = np.array([[0, 0, 0, 1], [0, 0, s, np.cos(np.pi / 4)], [0, 0, 1, 0]], np.float32)
    if interpolation == "CUBICSPLINE":
        z = np.zeros_like(rots)
        rots = np.stack([z, rots, z], axis=1).reshape(-1, 4)
    sp_idx = np.array([1], np.uint16)
    sp_val = np.array([[5.0, 0, 0]], np.float32)
    arrays = [pos, idx, joints, weights, ibm, times, rots, sp_idx, sp_val]
    blob, views = _pack(arrays)
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "spot", "color": [1, 0.5, 0.25], "intensity": 3.0, "spot": {"outerConeAngle": 0.5}}]}},
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": o, "byteLength": n} for o, n in views],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 2, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 2, "componentType": 5121, "count": 4, "type": "VEC4"},
            {"bufferView": 3, "componentType": 5121 if weights_u8 else 5126, "count": 4, "type": "VEC4",
             "normalized": weights_u8},
            {"bufferView": 4, "componentType": 5126, "count": 2, "type": "MAT4"},
            {"bufferView": 5, "componentType": 5126, "count": 3, "type": "SCALAR", "min": [0], "max": [2]},
            {"bufferView": 6, "componentType": 5126, "count": len(rots), "type": "VEC4"},
        ],
        "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3},
                                                    "indices": 1}]},
                   {"name": "box", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": 4, "skeleton": 1}],
        "nodes": [
            {"name": "body", "mesh": 0, "skin": 0},
            {"name": "hip", "children": [2], "translation": [0, 0, 0]},
            {"name": "spine", "translation": [0, 1, 0], "children": [3]},
            {"name": "hat", "mesh": 1, "translation": [0, 1, 0], "scale": [2, 2, 2]},
            {"name": "lamp", "translation": [0, 5, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "eye", "camera": 0, "translation": [0, 1, 10]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.1, "zfar": 100, "aspectRatio": 1.5}}],
        "scenes": [{"nodes": [0, 1, 4, 5]}],
        "scene": 0,
        "animations": [{"name": "bend", "samplers": [{"input": 5, "output": 6, "interpolation": interpolation}],
                        "channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}]}],
    }
    if sparse:
        doc["accessors"].append({"componentType": 5126, "count": 4, "type": "VEC3", "sparse": {
            "count": 1, "indices": {"bufferView": 7, "componentType": 5123}, "values": {"bufferView": 8}}})
        doc["meshes"][1]["primitives"][0]["attributes"]["POSITION"] = 7
    if extra:
        extra(doc)
    p = tmp_path / "synthetic.gltf"
    p.write_text(json.dumps(doc))
    return p


def test_synthetic_skin_rigid_light_camera(tmp_path):
    m = load_gltf(_synthetic(tmp_path))
    sk = m.skeleton
    assert sk.names[:3] == ["hip", "spine", "hat"]
    assert list(sk.parents[:3]) == [-1, 0, 1]
    assert list(sk.is_joint[:3]) == [True, True, False]
    quad = next(mm for mm in m.meshes if mm.name == "quad")
    hat = next(mm for mm in m.meshes if mm.name == "box")
    assert np.allclose(sk.skin_matrices(), np.eye(4), atol=1e-6)
    # the rigid "hat" sits in world space at rest: node world = T(0,2,0) S(2)
    assert np.allclose(hat.positions[2], [2, 2 + 4, 0])
    assert np.all(hat.joints[:, 0] == sk.bone_index("hat"))
    # bend: spine rotates 180 deg about Z at t=2 -> the top vertex (weight 1 on spine) maps to (0,0,0)
    pose = m.clips["bend"].sample(2.0)
    s = sk.skin_matrices(pose)
    top = s[sk.bone_index("spine")] @ np.array([0, 2, 0, 1.0])
    assert np.allclose(top[:3], [0, 0, 0], atol=1e-6)
    # the hat follows the spine rigidly
    hat_top = s[sk.bone_index("hat")] @ np.r_[hat.positions[3], 1.0]
    assert np.allclose(hat_top[:3], [0, 1 - 5, 0], atol=1e-5)
    assert np.allclose(quad.weights[2], [0.5, 0.5, 0, 0])
    # lights and cameras as piste's own (piste.scene_data), Z up: glTF (x, y, z) is piste (x, -z, y)
    from piste.scene_data import SpotLight

    (light,) = m.lights
    assert isinstance(light, SpotLight) and light.name == "lamp" and light.outer_angle == pytest.approx(np.degrees(0.5))
    assert light.intensity == pytest.approx(1 / 9)  # 3 cd without a range: the range where I/d^2 falls to white/256
    assert np.allclose(light.position, [0, 0, 5]) and np.allclose(light.direction, [0, 1, 0])
    (cam,) = m.cameras
    assert cam.name == "eye" and cam.fov_y == pytest.approx(np.degrees(0.7)) and cam.aspect == 1.5
    assert np.allclose(cam.eye, [0, -10, 1]) and np.allclose(cam.forward, [0, 1, 0]) and np.allclose(cam.up, [0, 0, 1])
    assert (cam.near, cam.far) == (pytest.approx(0.1), pytest.approx(100.0))


def test_step_interpolation(tmp_path):
    m = load_gltf(_synthetic(tmp_path, interpolation="STEP"))
    clip = m.clips["bend"]
    j = m.skeleton.bone_index("spine")
    assert np.allclose(clip.sample(0.99).rotation[j], [0, 0, 0, 1])
    assert np.allclose(clip.sample(1.0).rotation[j], [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])


def test_cubicspline_interpolation(tmp_path):
    m = load_gltf(_synthetic(tmp_path, interpolation="CUBICSPLINE"))
    clip = m.clips["bend"]
    j = m.skeleton.bone_index("spine")
    tr = clip.tracks["spine"]["rotation"]
    assert tr.interpolation == "CUBICSPLINE" and tr.n_keys == 3
    # zero tangents: Hermite with u=0.5 gives the midpoint of the keys, then normalised
    q = clip.sample(0.5).rotation[j]
    mid = (np.array([0, 0, 0, 1.0]) + np.array([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])) / 2
    assert np.allclose(q, mid / np.linalg.norm(mid))
    assert np.allclose(clip.sample(2.0).rotation[j], [0, 0, 1, 0])


def test_sparse_and_normalized_weights(tmp_path):
    m = load_gltf(_synthetic(tmp_path, sparse=True, weights_u8=True))
    hat = next(mm for mm in m.meshes if mm.name == "box")
    # sparse accessor with no bufferView: zeros with vertex 1 replaced by (5, 0, 0), then placed
    assert np.allclose(hat.positions[1], [0 + 10, 2, 0])
    assert np.allclose(hat.positions[0], [0, 2, 0])
    quad = next(mm for mm in m.meshes if mm.name == "quad")
    assert np.allclose(quad.weights[2], [128 / 255, 127 / 255, 0, 0], atol=1e-6)
    assert np.allclose(quad.weights.sum(1), 1)


def test_glb_roundtrip(tmp_path):
    src = _synthetic(tmp_path)
    g = pygltflib.GLTF2().load(str(src))
    g.convert_buffers(pygltflib.BufferFormat.BINARYBLOB)
    out = tmp_path / "synthetic.glb"
    g.save_binary(str(out))
    a = load_gltf(src)
    b = load_gltf(out)
    assert [mm.name for mm in a.meshes] == [mm.name for mm in b.meshes]
    assert np.array_equal(a.meshes[0].positions, b.meshes[0].positions)
    assert np.allclose(a.clips["bend"].sample(1.3).rotation, b.clips["bend"].sample(1.3).rotation)


# ---------------------------------------------------------------------------------------------- malformed
def _broken(tmp_path, mutate):
    return _synthetic(tmp_path, extra=mutate)


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda d: d["accessors"][0].update(count=400), "accessors[0]"),
        (lambda d: d["accessors"][0].update(componentType=5123), "accessors[0]"),
        (lambda d: d["accessors"][0].update(type="VEC2"), "accessors[0]"),
        (lambda d: d["accessors"][1].update(componentType=5126), "indices"),
        (lambda d: d["meshes"][0]["primitives"][0].update(indices=99), "accessors[99]"),
        (lambda d: d["nodes"][1].update(children=[42]), "nodes[1].children"),
        (lambda d: d["skins"][0].update(joints=[1, 77]), "skins[0].joints[1]"),
        (lambda d: d["bufferViews"][0].update(byteLength=10 ** 6), "bufferViews[0]"),
        (lambda d: d["animations"][0]["channels"][0].update(sampler=3), "animations[0].channels[0].sampler"),
        (lambda d: d["animations"][0]["samplers"][0].update(interpolation="QUADRATIC"), "interpolation"),
        (lambda d: d["accessors"][2].update(componentType=5126), "JOINTS_0"),
        (lambda d: d["buffers"][0].update(byteLength=10 ** 6), "buffers[0]"),
        (lambda d: d["nodes"][4]["extensions"]["KHR_lights_punctual"].update(light=3), "KHR_lights_punctual"),
    ],
)
def test_malformed_synthetic_names_field(tmp_path, mutate, field):
    p = _broken(tmp_path, mutate)
    with pytest.raises(FormatError) as e:
        load_gltf(p)
    assert field in str(e.value)
    assert str(p) in str(e.value)


def _rewrite_buffer(tmp_path, fn):
    """Synthetic file whose buffer bytes are modified by ``fn(bytearray, views)``."""
    p = _synthetic(tmp_path)
    doc = json.loads(p.read_text())
    blob = bytearray(base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]))
    fn(blob, [(v["byteOffset"], v["byteLength"]) for v in doc["bufferViews"]])
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
    p.write_text(json.dumps(doc))
    return p


def test_nan_weights_rejected(tmp_path):
    p = _rewrite_buffer(tmp_path, lambda b, v: b.__setitem__(slice(v[3][0], v[3][0] + 4), struct.pack("<f", np.nan)))
    with pytest.raises(FormatError, match=r"WEIGHTS_0.*accessors\[3\].*not finite"):
        load_gltf(p)


def test_bad_vertex_index_rejected(tmp_path):
    p = _rewrite_buffer(tmp_path, lambda b, v: b.__setitem__(slice(v[1][0], v[1][0] + 2), struct.pack("<H", 9)))
    with pytest.raises(FormatError, match="vertex index 9 out of range"):
        load_gltf(p)


def test_bad_joint_index_rejected(tmp_path):
    p = _rewrite_buffer(tmp_path, lambda b, v: b.__setitem__(v[2][0], 7))
    with pytest.raises(FormatError, match="JOINTS_0.*out of range"):
        load_gltf(p)


@needs_data
def test_missing_external_buffer(tmp_path):
    d = tmp_path / "m"
    shutil.copytree(_file("SimpleMorph").parent, d)
    (d / "simpleMorphAnimation.bin").unlink()
    with pytest.raises(FormatError, match=r"buffers\[1\].uri"):
        load_gltf(d / "SimpleMorph.gltf")


@needs_data
def test_truncated_external_buffer(tmp_path):
    d = tmp_path / "m"
    shutil.copytree(_file("MorphPrimitivesTest").parent, d)
    b = d / "MorphPrimitivesTest.bin"
    b.chmod(0o644)
    b.write_bytes(b.read_bytes()[:100])
    with pytest.raises(FormatError, match=r"buffers\[0\].byteLength"):
        load_gltf(d / "MorphPrimitivesTest.gltf")


@needs_data
def test_corrupt_glb_and_missing_file(tmp_path):
    src = _file("RiggedSimple").read_bytes()
    bad = tmp_path / "bad.glb"
    bad.write_bytes(src[:200])
    with pytest.raises(PisteError):
        load_gltf(bad)
    with pytest.raises(FormatError, match="no such file"):
        load_gltf(tmp_path / "nope.glb")
    junk = tmp_path / "junk.gltf"
    junk.write_text("{ not json")
    with pytest.raises(FormatError):
        load_gltf(junk)
