"""glTF extensions on import: Draco and quantized files made here from the shared sample models
(DracoPy encodes, pygltflib writes), extensionsRequired refused by name, materials."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from piste.errors import FormatError
from piste.formats.gltf import load_gltf
from piste.formats.gltf_ext import SUPPORTED, texture_transform_matrix

DATA = Path("/work/shared/data/gltf")
if not DATA.is_dir():
    DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "gltf"
CESIUM = DATA / "CesiumMan" / "CesiumMan.glb"


def _arrays(g, i):
    a = g.accessors[i]
    bv = g.bufferViews[a.bufferView]
    dt = {5126: "<f4", 5121: "u1", 5123: "<u2", 5125: "<u4"}[a.componentType]
    nc = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a.type]
    return np.frombuffer(g.binary_blob(), dt, count=a.count * nc, offset=bv.byteOffset + (a.byteOffset or 0)).reshape(a.count, nc)


def _dracoify(src, dst, bits=14, corrupt=False):
    """CesiumMan with its primitive's attributes and indices Draco-compressed (accessors lose
    their bufferViews, as the extension specifies)."""
    import DracoPy

    g = pygltflib.GLTF2().load(str(src))
    prim = g.meshes[0].primitives[0]
    at = prim.attributes
    pos, nrm, uv = _arrays(g, at.POSITION), _arrays(g, at.NORMAL), _arrays(g, at.TEXCOORD_0)
    joints, weights = _arrays(g, at.JOINTS_0), _arrays(g, at.WEIGHTS_0)
    faces = _arrays(g, prim.indices).reshape(-1, 3)
    data = DracoPy.encode(pos.astype(np.float64), faces.astype(np.uint32), quantization_bits=bits,
                          normals=nrm.astype(np.float64), tex_coord=uv.astype(np.float64), preserve_order=True,
                          generic_attributes={100: joints.astype(np.uint16), 101: weights.astype(np.float32)})
    m = DracoPy.decode(data)
    ids = {a["attribute_type"]: a["unique_id"] for a in m.attributes if a["attribute_type"] != 4}
    if corrupt:
        data = data[:40] + bytes(len(data) - 40)
    blob = bytearray(g.binary_blob())
    blob.extend(b"\0" * ((-len(blob)) % 4))
    off = len(blob)
    blob.extend(data)
    blob.extend(b"\0" * ((-len(blob)) % 4))
    g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=off, byteLength=len(data)))
    for i in (at.POSITION, at.NORMAL, at.TEXCOORD_0, at.JOINTS_0, at.WEIGHTS_0, prim.indices):
        g.accessors[i].bufferView = None
        g.accessors[i].byteOffset = None
    prim.extensions = {"KHR_draco_mesh_compression": {
        "bufferView": len(g.bufferViews) - 1,
        "attributes": {"POSITION": ids[0], "NORMAL": ids[1], "TEXCOORD_0": ids[3], "JOINTS_0": 100, "WEIGHTS_0": 101}}}
    g.extensionsUsed = sorted(set(g.extensionsUsed or []) | {"KHR_draco_mesh_compression"})
    g.extensionsRequired = ["KHR_draco_mesh_compression"]
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    g.save(str(dst))
    return dst


def test_draco_decodes_to_the_original(tmp_path):
    pytest.importorskip("DracoPy")
    ref = load_gltf(CESIUM)
    back = load_gltf(_dracoify(CESIUM, tmp_path / "draco.glb"))
    a, b = ref.meshes[0], back.meshes[0]
    size = float(np.ptp(a.positions, axis=0).max())
    err = np.abs(b.positions - a.positions).max()
    assert 0 < err <= size / 2 ** 13, err  # 14-bit quantization, not zeros
    assert np.array_equal(b.indices, a.indices)
    assert np.allclose(b.uv, a.uv, atol=1e-6) and np.allclose(b.normals, a.normals, atol=1e-5)
    assert np.array_equal(b.joints, a.joints) and np.allclose(b.weights, a.weights, atol=1e-6)
    # the skin still works: posed positions agree
    clip = next(iter(ref.clips))
    pa = ref.skeleton.skin_matrices(ref.clips[clip].sample(0.4, ref.skeleton))
    from piste.character import skin

    p0, _ = skin(a, pa)
    p1, _ = skin(b, pa)
    assert np.abs(p1 - p0).max() <= 2 * size / 2 ** 13


def test_draco_corrupt_raises_never_zeros(tmp_path):
    pytest.importorskip("DracoPy")
    p = _dracoify(CESIUM, tmp_path / "bad.glb", corrupt=True)
    with pytest.raises(FormatError, match="KHR_draco_mesh_compression"):
        load_gltf(p)


def test_draco_without_dracopy_names_the_extra(tmp_path, monkeypatch):
    pytest.importorskip("DracoPy")
    p = _dracoify(CESIUM, tmp_path / "d.glb")
    monkeypatch.setitem(sys.modules, "DracoPy", None)  # import fails
    with pytest.raises(FormatError, match=r"needs the 'gltf' extra: pip install 'piste\[gltf\]'"):
        load_gltf(p)


@pytest.mark.parametrize("name", ["EXT_meshopt_compression", "KHR_texture_basisu", "MSFT_made_up"])
def test_unsupported_required_extension_refused_by_name(tmp_path, name):
    g = pygltflib.GLTF2().load(str(CESIUM))
    g.extensionsUsed = [name]
    g.extensionsRequired = [name]
    p = tmp_path / "req.glb"
    g.save(str(p))
    with pytest.raises(FormatError, match=f"requires extension '{name}'") as e:
        load_gltf(p)
    assert "extensionsRequired[0]" in str(e.value)


def test_supported_list():
    assert {"KHR_draco_mesh_compression", "KHR_mesh_quantization", "KHR_texture_transform"} <= set(SUPPORTED)


def _quantized(tmp_path, with_ext=True):
    """CesiumMan's mesh (bind pose, unskinned) written with KHR_mesh_quantization: positions
    uint16 dequantized by the node's scale/translation, normals normalized int8, UVs normalized
    uint16."""
    m = load_gltf(CESIUM).meshes[0]
    p = m.positions.astype(np.float64)
    lo, hi = p.min(0), p.max(0)
    step = (hi - lo) / 65535.0
    qp = np.round((p - lo) / step).astype(np.uint16)
    nq = m.normals.astype(np.float64) * step  # normals in the quantized space: S n (the node's S^-T undoes it)
    nq /= np.linalg.norm(nq, axis=1, keepdims=True)
    qn = np.round(np.clip(nq, -1, 1) * 127).astype(np.int8)
    qn4 = np.zeros((len(qn), 4), np.int8)
    qn4[:, :3] = qn  # 4-byte aligned elements
    qu = np.round(np.clip(m.uv, 0, 1) * 65535).astype(np.uint16)
    idx = m.indices.astype(np.uint32).reshape(-1)
    parts = [qp.tobytes(), qn4.tobytes(), qu.tobytes(), idx.tobytes()]
    blob, views = b"", []
    for data in parts:
        blob += b"\0" * ((-len(blob)) % 4)
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob += data
    blob += b"\0" * ((-len(blob)) % 4)
    views[0].byteStride = 8
    views[0].byteLength = len(qp) * 8 - 2
    # re-lay positions with stride 8 (uint16 x3 + 2 padding bytes)
    pp = np.zeros((len(qp), 4), np.uint16)
    pp[:, :3] = qp
    blob = pp.tobytes() + blob[len(qp.tobytes()) + ((-len(qp.tobytes())) % 4):]
    shift = len(pp.tobytes()) - (len(qp.tobytes()) + ((-len(qp.tobytes())) % 4))
    for v in views[1:]:
        v.byteOffset += shift
    views[1].byteStride = 4
    nv = len(qp)
    acc = [pygltflib.Accessor(bufferView=0, componentType=5123, count=nv, type="VEC3",
                              min=[int(x) for x in qp.min(0)], max=[int(x) for x in qp.max(0)]),
           pygltflib.Accessor(bufferView=1, componentType=5120, count=nv, type="VEC3", normalized=True),
           pygltflib.Accessor(bufferView=2, componentType=5123, count=nv, type="VEC2", normalized=True),
           pygltflib.Accessor(bufferView=3, componentType=5125, count=len(idx), type="SCALAR")]
    g = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0"), scene=0, scenes=[pygltflib.Scene(nodes=[0])],
        nodes=[pygltflib.Node(mesh=0, translation=[float(x) for x in lo], scale=[float(x) for x in step])],
        meshes=[pygltflib.Mesh(primitives=[pygltflib.Primitive(
            attributes=pygltflib.Attributes(POSITION=0, NORMAL=1, TEXCOORD_0=2), indices=3)])],
        accessors=acc, bufferViews=views, buffers=[pygltflib.Buffer(byteLength=len(blob))])
    if with_ext:
        g.extensionsUsed = ["KHR_mesh_quantization"]
        g.extensionsRequired = ["KHR_mesh_quantization"]
    g.set_binary_blob(blob)
    out = tmp_path / ("q.glb" if with_ext else "q_noext.glb")
    g.save(str(out))
    return out, m, step


def test_mesh_quantization(tmp_path):
    out, m, step = _quantized(tmp_path)
    back = load_gltf(out).meshes[0]
    # the node's scale/translation dequantize (scale is non-uniform, so normals go through the
    # inverse transpose: compare directions)
    assert np.abs(back.positions - m.positions).max() <= 0.51 * step.max() + 1e-6
    assert np.allclose(np.linalg.norm(back.normals, axis=1), 1.0, atol=1e-5)
    assert np.degrees(np.arccos(np.clip((back.normals * m.normals).sum(1), -1, 1))).max() < 1.5
    assert np.abs(back.uv - m.uv).max() <= 1.0 / 65535 + 1e-7
    assert np.array_equal(back.indices, m.indices)


def test_integer_positions_without_the_extension_refused(tmp_path):
    out, _, _ = _quantized(tmp_path, with_ext=False)
    with pytest.raises(FormatError, match="POSITION"):
        load_gltf(out)


def test_materials_alpha_sides_transform_emissive_unlit(tmp_path):
    g = pygltflib.GLTF2().load(str(CESIUM))
    d = json.loads(g.to_json())
    mat = d["materials"][0]
    mat["alphaMode"] = "MASK"
    mat["alphaCutoff"] = 0.3
    mat["doubleSided"] = True
    mat["emissiveFactor"] = [1.0, 0.5, 0.0]
    mat["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}, "KHR_materials_unlit": {}}
    mat["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
        "KHR_texture_transform": {"offset": [0.25, 0.5], "rotation": 0.3, "scale": [2.0, 3.0]}}
    d["extensionsUsed"] = ["KHR_texture_transform", "KHR_materials_emissive_strength", "KHR_materials_unlit"]
    d["extensionsRequired"] = ["KHR_texture_transform"]
    g2 = pygltflib.GLTF2.from_json(json.dumps(d))
    g2.set_binary_blob(g.binary_blob())
    p = tmp_path / "mat.glb"
    g2.save(str(p))
    ref = load_gltf(CESIUM).meshes[0]
    m = load_gltf(p).meshes[0]
    info = m.material
    assert info.alpha_mode == "MASK" and info.alpha_cutoff == pytest.approx(0.3) and info.double_sided
    assert np.allclose(info.emissive, [4.0, 2.0, 0.0]) and info.unlit
    t = texture_transform_matrix((0.25, 0.5), 0.3, (2.0, 3.0))
    want = ref.uv.astype(np.float64) @ t[:2, :2].T + t[:2, 2]
    assert np.allclose(m.uv, want, atol=1e-5)
    assert m.texture is not None and m.texture.shape == ref.texture.shape
    # the spec's own example: offset then rotation then scale, uv' = T R S uv
    c, s = np.cos(0.3), np.sin(0.3)
    assert np.allclose(t @ [1.0, 0.0, 1.0], [0.25 + 2 * c, 0.5 - 2 * s, 1.0])
    # bad alpha mode: a FormatError naming the field
    d2 = copy.deepcopy(d)
    d2["materials"][0]["alphaMode"] = "SOMETIMES"
    g3 = pygltflib.GLTF2.from_json(json.dumps(d2))
    g3.set_binary_blob(g.binary_blob())
    g3.save(str(tmp_path / "bad.glb"))
    with pytest.raises(FormatError, match="alphaMode"):
        load_gltf(tmp_path / "bad.glb")


def test_document_reads_like_pygltflib():
    """gltf_ext.Document (what load_gltf reads through) gives the same fields and binary chunk as
    pygltflib's own parse on every sample model."""
    from piste.formats.gltf_ext import read_document
    from piste.formats.gltf.schema import precheck_gltf

    files = sorted(p for p in DATA.glob("*/*") if p.suffix.lower() in (".glb", ".gltf"))
    assert len(files) >= 8
    for f in files:
        a = read_document(f, precheck_gltf(f))
        b = pygltflib.GLTF2().load(str(f))
        assert (a.binary_blob() is None) == (b.binary_blob() is None)
        if a.binary_blob() is not None:
            assert a.binary_blob()[:len(b.binary_blob())] == b.binary_blob()
        assert [n.name for n in a.nodes or []] == [n.name for n in b.nodes or []]
        assert [x.count for x in a.accessors] == [x.count for x in b.accessors]
        for ma, mb in zip(a.meshes or [], b.meshes or []):
            for pa, pb in zip(ma.primitives, mb.primitives):
                assert pa.attributes.POSITION == pb.attributes.POSITION and pa.indices == pb.indices
        assert a.nodes[0].no_such_field is None and a.extensions is None or isinstance(a.extensions, dict)
