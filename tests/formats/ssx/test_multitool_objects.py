"""The Multitool's ``Instances.json``, ``Splines.json`` and ``Models.json`` (issue 22).

Projects here are built from the documented field layout (SSX-Library's ``InstanceJson``,
``SplineJson``, ``ModelJson`` structs: keys in declaration order, float32 values as Json.NET
writes them), never from a retail file.  ``.pbd`` records are checked with ``struct`` in the field
order of ``PBDHandler.cs`` (instance: 16 f32 matrix, 16 f32 light matrix, 16 f32 colours, 3 i32,
6 f32 bounds, 7 i32; spline: 6 f32, 4 i32; segment: 16 f32, 4 f32, 3 i32, 6 f32, 2 f32, i32),
independently of piste's dtypes.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.ssx import parse_pbd, read_pbd
from piste.formats.ssx.multitool import read_project, write_project
from piste.formats.ssx.multitool_objects import (
    INSTANCE_DTYPE, SEGMENT_DTYPE, SEGMENT_UNKNOWN32, SPLINE_DTYPE, compose_rows, decompose_rows, segment_records,
)
from piste.formats.ssx.pbd import hash_section_bytes
from piste.formats.ssx.synth import pbd_bytes
from piste.pipeline.ssx_synth import make_level


def f32(x) -> float:
    return float(str(np.float32(x)))


def _sound():
    return {"CollisonSound": 3, "ExternalSounds": [
        {"U0": 1, "SoundIndex": 12, "U2": 0.5, "U3": f32(1 / 3), "U4": -2.25, "U5": 1500.0, "U6": 0.0}]}


def _instance(i: int) -> dict:
    """An InstanceJson object as the Multitool writes it (every key, declaration order)."""
    return {
        "InstanceName": f"tree_{i}", "Location": [f32(1234.5 + i), f32(-987.25), f32(0.1 * i)],
        "Rotation": [0.0, 0.0, f32(np.sin(0.3 * i)), f32(np.cos(0.3 * i))], "Scale": [1.0, f32(1.5 + i), 1.0],
        "LightVector1": [0.0, f32(0.6), -0.8, 0.0], "LightVector2": [1.0, 0.0, 0.0, 0.0],
        "LightVector3": [0.0, 1.0, 0.0, 0.0], "AmbentLightVector": [0.0, 0.0, 0.0, 1.0],
        "LightColour1": [f32(0.7), f32(0.7), f32(0.65), 1.0], "LightColour2": [0.1, 0.1, 0.1, 1.0],
        "LightColour3": [0.0, 0.0, 0.0, 1.0], "AmbentLightColour": [f32(0.35), f32(0.38), 0.5, 1.0],
        "ModelID": i % 2, "PrevInstance": -1, "NextInstance": -1, "UnknownInt26": 0, "UnknownInt27": 5,
        "UnknownInt28": -1, "UnknownInt30": 2**31 - 1, "UnknownInt31": -2**31, "UnknownInt32": 7,
        "LTGState": 2, "Hash": -1190211347 + i, "IncludeSound": i == 0, "Sounds": _sound() if i == 0 else None,
        "U0": f32(0.25), "PlayerBounceAmmount": 1.5, "U2": 4, "Visable": True, "PlayerCollision": i == 1,
        "PlayerBounce": False, "Unknown241": True, "UVScroll": False, "SurfaceType": 9, "CollsionMode": 1,
        "CollsionModelPaths": ["12.obj", "13.obj"] if i == 1 else None, "EffectSlotIndex": -1,
        "PhysicsIndex": 2, "U8": 0,
    }


def _spline(i: int) -> dict:
    pts = [[[f32(100.0 * (3 * s + k) + i), f32(50.0 * k * k), f32(-20.0 * s - k)] for k in range(4)]
           for s in range(2 + i)]
    for s in range(1, len(pts)):
        pts[s][0] = pts[s - 1][3]
    return {"SplineName": f"racing_line_{i}", "U0": 1, "U1": -1, "SplineStyle": 3 + i,
            "Segments": [{"Points": p} for p in pts]}


def _model(i: int) -> dict:
    anim = {"U1": 0.5, "U2": 1.0, "U3": 0.0, "U4": 0.0, "U5": 0.0, "U6": f32(0.1), "AnimationAction": 2,
            "AnimationEntries": [{"AnimationMaths": [{f"Value{v}": float(v) for v in range(1, 7)}]}]}
    return {"ModelName": f"tree_model_{i}", "Unknown3": 1, "AnimTime": f32(2.5), "ModelObjects": [
        {"ObjectName": "Model Object 0", "ParentID": -1, "Flags": 64, "Animation": anim if i else None,
         "MeshData": [{"MeshPath": f"{i}.obj", "MaterialID": 3}], "Position": [0.0, 0.0, 10.0],
         "Rotation": [0.0, 0.0, 0.0, 1.0], "Scale": [1.0, 1.0, 1.0], "IncludeAnimation": bool(i),
         "IncludeMatrix": True},
        {"ObjectName": "Model Object 1", "ParentID": 0, "Flags": 0, "Animation": None, "MeshData": [],
         "Position": None, "Rotation": None, "Scale": None, "IncludeAnimation": False, "IncludeMatrix": False}]}


def _multitool_project(folder, level):
    """A project as the Multitool writes one: piste writes Patches.json etc.; the three files are
    replaced by the documented layout, piste's record of the level removed."""
    write_project(folder, level.pbd, level.textures, level.lightmaps)
    for f in ("PisteLevel.json", "PisteLevel.pbd"):
        (folder / f).unlink()
    docs = {"Instances.json": {"Instances": [_instance(i) for i in range(3)]},
            "Splines.json": {"Splines": [_spline(i) for i in range(2)]},
            "Models.json": {"Models": [_model(i) for i in range(2)]}}
    for name, doc in docs.items():
        (folder / name).write_text(json.dumps(doc))  # Formatting.None, as the Multitool's default
    return docs


@pytest.fixture(scope="module")
def level():
    return make_level(rows=2, cols=2, seed=4, n_textures=2)


# ----------------------------------------------------------------------------- JSON round trip
def test_multitool_files_come_back_field_for_field(level, tmp_path):
    docs = _multitool_project(tmp_path / "mt", level)
    proj = read_project(tmp_path / "mt")
    assert (len(proj.instances), len(proj.splines), len(proj.models)) == (3, 2, 2)
    write_project(tmp_path / "out", level.pbd, level.textures, level.lightmaps, instances=proj.instances,
                  splines=proj.splines, models=proj.models)
    for name, doc in docs.items():
        back = json.loads((tmp_path / "out" / name).read_text())
        assert back == doc, name
        # keys in the structs' declaration order (as Json.NET writes them)
        assert [list(d) for d in back[name[:-5]]] == [list(d) for d in doc[name[:-5]]]
    assert proj.models.mesh_paths == ["0.obj", "1.obj"]


def test_left_out_keys_are_the_csharp_defaults_and_nonfinite_floats_are_strings(level, tmp_path):
    _multitool_project(tmp_path / "mt", level)
    d = _instance(0)
    for key in ("InstanceName", "Sounds", "LTGState", "Visable", "U0", "CollsionModelPaths"):
        del d[key]
    d["LightColour2"] = ["NaN", "Infinity", "-Infinity", 0.0]
    d["UnknownKey"] = 5  # ignored, as Json.NET ignores it
    (tmp_path / "mt" / "Instances.json").write_text(json.dumps({"Instances": [d]}))
    proj = read_project(tmp_path / "mt")
    write_project(tmp_path / "out", level.pbd, instances=proj.instances)
    back = json.loads((tmp_path / "out" / "Instances.json").read_text())["Instances"][0]
    assert back["InstanceName"] is None and back["Sounds"] is None and back["CollsionModelPaths"] is None
    assert back["LTGState"] == 0 and back["Visable"] is False and back["U0"] == 0
    assert back["LightColour2"] == ["NaN", "Infinity", "-Infinity", 0.0] and "UnknownKey" not in back
    assert proj.instances.names == ["Instance_0"]


# ----------------------------------------------------------------------------- placements
def test_compose_follows_system_numerics():
    """CreateScale(S) * CreateFromQuaternion(q), row vectors: a quarter turn about z takes +x to +y."""
    q = [0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    m = compose_rows([[10.0, 20.0, 30.0]], [q], [[2.0, 1.0, 1.0]])[0]
    np.testing.assert_allclose(np.array([1.0, 0, 0, 1]) @ m, [10.0, 22.0, 30.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(np.array([0.0, 1, 0, 1]) @ m, [9.0, 20.0, 30.0, 1.0], atol=1e-12)
    rng = np.random.default_rng(1)
    qs = rng.normal(size=(40, 4))
    qs /= np.linalg.norm(qs, axis=1, keepdims=True)
    scales = rng.uniform(0.1, 4, (40, 3)) * np.where(rng.random((40, 3)) < 0.2, -1, 1)
    mats = compose_rows(rng.normal(size=(40, 3)) * 1e3, qs, scales)
    np.testing.assert_allclose(compose_rows(*decompose_rows(mats)), mats, atol=1e-9)


def test_placements_are_piste_object_matrices_in_metres(level, tmp_path):
    _multitool_project(tmp_path / "mt", level)
    inst = read_project(tmp_path / "mt").instances
    pl = inst.placements()
    assert pl["names"] == ["tree_0", "tree_1", "tree_2"] and pl["model"].tolist() == [0, 1, 0]
    m = pl["matrix"]
    rows = compose_rows(inst.location, inst.rotation, inst.scale)
    p = np.array([30.0, -20.0, 5.0])  # a model point (the model converted to metres)
    for i in range(3):
        world_cm = np.append(p * 100, 1) @ rows[i]
        np.testing.assert_allclose(m[i] @ np.append(p, 1), np.append(world_cm[:3] / 100, 1), atol=1e-9)


def test_piste_placements_written_as_instances_and_back(level, tmp_path):
    """piste's placed objects (column matrices, metres) -> Instances.json -> the same placements."""
    from piste.formats.ssx.multitool_objects import instances_from_placements, instances_json

    rng = np.random.default_rng(3)
    q = rng.normal(size=(5, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rows = compose_rows(rng.uniform(-3e4, 3e4, (5, 3)), q, rng.uniform(0.5, 2, (5, 3)))
    m = rows.transpose(0, 2, 1).copy()
    m[:, :3, 3] /= 100  # piste's metres
    colours = rng.uniform(0, 1, (5, 4, 4))
    inst = instances_from_placements(m, [0, 1, 2, 1, 0], names=[f"rock_{i}" for i in range(5)],
                                     light_colours=colours)
    (tmp_path / "Instances.json").write_text(json.dumps(instances_json(inst)))
    from piste.formats.ssx.multitool_objects import instances_from_json

    back = instances_from_json(json.loads((tmp_path / "Instances.json").read_text()), "Instances.json")
    pl = back.placements()
    assert pl["names"][4] == "rock_4" and pl["model"].tolist() == [0, 1, 2, 1, 0]
    np.testing.assert_allclose(pl["matrix"], m, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(back.items[2]["LightColour3"], colours[2, 2], rtol=1e-6)


def test_spline_polyline_is_the_bezier_in_metres(level, tmp_path):
    _multitool_project(tmp_path / "mt", level)
    spl = read_project(tmp_path / "mt").splines
    line = spl.polyline(1, samples=4)
    p = spl.points(1)
    assert line.shape == (3 * 4 + 1, 3)
    np.testing.assert_allclose(line[0], p[0, 0] / 100)
    np.testing.assert_allclose(line[-1], p[-1, 3] / 100)
    t = 0.5
    mid = (1 - t) ** 3 * p[1, 0] + 3 * (1 - t) ** 2 * t * p[1, 1] + 3 * (1 - t) * t ** 2 * p[1, 2] + t ** 3 * p[1, 3]
    np.testing.assert_allclose(line[4 + 2], mid / 100)


# ----------------------------------------------------------------------------- the .pbd side
def _instance_by_the_facts(raw: bytes, off: int) -> dict:
    v = struct.unpack_from("<16f16f16f3i6f7i", raw, off)
    return {"matrix": np.array(v[0:16]).reshape(4, 4), "light": np.array(v[16:32]).reshape(4, 4),
            "colour": np.array(v[32:48]).reshape(4, 4), "ids": v[48:51], "lowest": v[51:54], "highest": v[54:57],
            "ints": v[57:64]}


def _segment_by_the_facts(raw: bytes, off: int) -> dict:
    v = struct.unpack_from("<16f4f3i6f2fi", raw, off)
    return {"power": np.array(v[0:16]).reshape(4, 4), "coef": v[16:20], "links": v[20:23], "lowest": v[23:26],
            "highest": v[26:29], "length": v[29], "before": v[30], "u32": v[31]}


def _level_with_objects():
    """A level with 3 instances of 2 models, 2 splines (2 and 1 segments), their hashes."""
    lv = make_level(rows=2, cols=3, seed=5)
    rng = np.random.default_rng(2)
    inst = np.zeros(3, INSTANCE_DTYPE)
    q = np.array([[0, 0, 0, 1], [0, 0, np.sin(0.4), np.cos(0.4)], [np.sin(0.1), 0, 0, np.cos(0.1)]])
    inst["matrix"] = compose_rows(rng.uniform(-5e3, 5e3, (3, 3)), q, [[1, 1, 1], [2, 2, 2], [1, 0.5, 3]])
    inst["light_matrix"] = rng.uniform(-1, 1, (3, 4, 4))
    inst["light_colour"] = rng.uniform(0, 1, (3, 4, 4))
    inst["model_id"] = inst["model_id2"] = [0, 1, 0]
    inst["prev"], inst["next"] = -1, -1
    inst["lowest"] = inst["matrix"][:, 3, :3] - 100
    inst["highest"] = inst["matrix"][:, 3, :3] + 100
    inst["unknown27"] = 11
    raw0 = rng.uniform(-1e4, 1e4, (2, 4, 3))
    raw0[1, 0] = raw0[0, 3]
    seg = np.concatenate([segment_records(raw0, 0, 0), segment_records(rng.uniform(-1e4, 1e4, (1, 4, 3)), 1, 2)])
    seg["coefficients"] = rng.uniform(-1, 1, (3, 4))  # a retail level's own fit: kept when not edited
    spl = np.zeros(2, SPLINE_DTYPE)
    spl[0] = (seg["lowest"][:2].min(0), seg["highest"][:2].max(0), 0, 2, 0, -1)
    spl[1] = (seg["lowest"][2], seg["highest"][2], 0, 1, 2, -1)
    head = 52
    hashes = struct.pack("<13I", head + 24 + 8, 0, head, 3, head, 0, head + 24, 1, head + 24, 0, head + 32, 0,
                         head + 32) + struct.pack("<6i", -50, 1, 9, 0, 70, 2) + struct.pack("<2i", 5, 0)
    sec = {"instances": (3, inst.tobytes()), "lights": (1, np.zeros(1, np.dtype("V92")).tobytes()),
           "splines": (2, spl.tobytes()), "spline_segments": (3, seg.tobytes()), "models": (2, rng.bytes(64)),
           "hash": (None, hashes), "mesh_data": (None, rng.bytes(64))}
    return parse_pbd(pbd_bytes(lv.pbd.records, 3, 1, sec)), lv


def test_convert_writes_the_levels_instances_and_splines(tmp_path):
    pbd, lv = _level_with_objects()
    write_project(tmp_path / "p", pbd)
    inst = json.loads((tmp_path / "p" / "Instances.json").read_text())["Instances"]
    spl = json.loads((tmp_path / "p" / "Splines.json").read_text())["Splines"]
    assert not (tmp_path / "p" / "Models.json").exists()  # piste does not decode models
    assert [d["InstanceName"] for d in inst] == ["Instance_0", "Instance_1", "Instance_2"]
    assert [d["Hash"] for d in inst] == [9, -50, 70] and [d["ModelID"] for d in inst] == [0, 1, 0]
    for i, d in enumerate(inst):
        rec = _instance_by_the_facts(pbd.raw, pbd.offsets["instances"] + 256 * i)
        np.testing.assert_allclose(compose_rows(d["Location"], d["Rotation"], d["Scale"])[0], rec["matrix"],
                                   rtol=1e-6, atol=1e-3)
        np.testing.assert_allclose(d["LightVector2"], rec["light"][:, 1], rtol=1e-6)
        np.testing.assert_allclose(d["AmbentLightColour"], rec["colour"][3], rtol=1e-6)
        assert d["UnknownInt27"] == 11 and d["Sounds"] is None and d["LTGState"] == 0
    assert [len(s["Segments"]) for s in spl] == [2, 1] and spl[0]["SplineName"] == "Spline_0"
    assert spl[0]["U0"] == spl[0]["SplineStyle"] == 0  # the .ssf's: piste does not read it
    seg0 = _segment_by_the_facts(pbd.raw, pbd.offsets["spline_segments"])
    p = np.array(spl[0]["Segments"][0]["Points"])
    t = 0.3  # the power basis (P3, P2, P1, P0 stored) and the Bézier agree
    c = seg0["power"][::-1, :3]
    bez = (1 - t) ** 3 * p[0] + 3 * (1 - t) ** 2 * t * p[1] + 3 * (1 - t) * t ** 2 * p[2] + t ** 3 * p[3]
    np.testing.assert_allclose(c[0] + c[1] * t + c[2] * t ** 2 + c[3] * t ** 3, bez, rtol=1e-5, atol=0.05)


def test_pbd_to_project_to_pbd_is_byte_identical(tmp_path):
    pbd, lv = _level_with_objects()
    write_project(tmp_path / "p", pbd, lv.textures, lv.lightmaps)
    out, _, _ = read_project(tmp_path / "p").to_level()
    assert out.to_bytes() == pbd.to_bytes()


def test_edited_instances_and_splines_are_written_in_place(tmp_path):
    pbd, lv = _level_with_objects()
    write_project(tmp_path / "p", pbd, lv.textures, lv.lightmaps)
    doc = json.loads((tmp_path / "p" / "Instances.json").read_text())
    d = doc["Instances"][1]
    d["Location"] = [100.0, 200.0, 300.0]
    d["Rotation"] = [0.0, 0.0, 0.0, 1.0]
    d["Scale"] = [2.0, 2.0, 2.0]
    d["LightColour3"] = [0.25, 0.5, 0.75, 1.0]
    d["ModelID"] = 0
    doc["Instances"][2]["Hash"] = -999
    (tmp_path / "p" / "Instances.json").write_text(json.dumps(doc))
    sdoc = json.loads((tmp_path / "p" / "Splines.json").read_text())
    sdoc["Splines"][0]["Segments"][1]["Points"][2] = [0.0, 0.0, 0.0]
    (tmp_path / "p" / "Splines.json").write_text(json.dumps(sdoc))
    out, _, _ = read_project(tmp_path / "p").to_level()
    io_, no = pbd.offsets["instances"], out.offsets["instances"]
    assert no == io_ and out.counts == pbd.counts
    for i in (0, 2):  # unchanged records keep their bytes
        assert out.raw[no + 256 * i:no + 256 * (i + 1)] == pbd.raw[io_ + 256 * i:io_ + 256 * (i + 1)]
    rec = _instance_by_the_facts(out.raw, no + 256)
    old = _instance_by_the_facts(pbd.raw, io_ + 256)
    np.testing.assert_array_equal(rec["matrix"], np.diag([2.0, 2, 2, 1]) + np.pad([[100.0, 200, 300]], ((3, 0), (0, 1))))
    np.testing.assert_allclose(rec["colour"][2], [0.25, 0.5, 0.75, 1.0])
    assert rec["ids"] == (0, -1, -1) and rec["ints"][3] == 0  # ModelID2 = ModelID (the Multitool's rebuild)
    # the old box, carried from the old placement to the new one
    inv = np.linalg.inv(old["matrix"])
    corners = np.array([[old["lowest"][a] if not (c >> a) & 1 else old["highest"][a] for a in range(3)] + [1.0]
                        for c in range(8)])
    moved = corners @ inv @ rec["matrix"]
    np.testing.assert_allclose(rec["lowest"], moved[:, :3].min(0), rtol=1e-5, atol=0.05)
    np.testing.assert_allclose(rec["highest"], moved[:, :3].max(0), rtol=1e-5, atol=0.05)
    # the hash list: sorted by hash, instance 2 now -999
    h = out.hash_header()
    pairs = struct.unpack_from("<6i", out.raw, out.offsets["hash"] + h["offset_instances"])
    assert pairs == (-999, 2, -50, 1, 9, 0)
    # splines: segment 1 of spline 0 rebuilt, the others keep their bytes
    so = out.offsets["spline_segments"]
    assert out.raw[so:so + 128] == pbd.raw[so:so + 128] and out.raw[so + 256:so + 384] == pbd.raw[so + 256:so + 384]
    seg = _segment_by_the_facts(out.raw, so + 128)
    p = np.array(sdoc["Splines"][0]["Segments"][1]["Points"], np.float64)
    np.testing.assert_allclose(seg["power"][3, :3], p[0], rtol=1e-6)  # constant term = first point, w = 1
    assert seg["power"][3, 3] == 1.0 and seg["power"][0, 3] == 0.0
    np.testing.assert_allclose(seg["power"][0, :3], -p[0] + 3 * p[1] - 3 * p[2] + p[3], rtol=1e-5, atol=0.05)
    assert seg["links"] == (0, -1, 0) and seg["u32"] == SEGMENT_UNKNOWN32
    np.testing.assert_allclose(seg["length"], np.linalg.norm(np.diff(p, axis=0), axis=1).sum(), rtol=1e-6)
    assert seg["before"] == _segment_by_the_facts(out.raw, so)["length"]
    np.testing.assert_allclose(seg["lowest"], p.min(0), rtol=1e-6)
    # the arc-length cubic: the least-squares cubic t(s), s the distance along 200 samples in metres
    t = np.linspace(0, 1, 200)
    curve = (1 - t)[:, None] ** 3 * p[0] + 3 * ((1 - t) ** 2 * t)[:, None] * p[1] + \
        3 * ((1 - t) * t ** 2)[:, None] * p[2] + (t ** 3)[:, None] * p[3]
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))]) / 100
    ref = np.polyfit(s, t, 3)
    np.testing.assert_allclose(np.polyval(seg["coef"], s), np.polyval(ref, s), atol=1e-5)
    sp = struct.unpack_from("<6f4i", out.raw, out.offsets["splines"])
    np.testing.assert_allclose(sp[0:3], np.minimum(p.min(0), _segment_by_the_facts(out.raw, so)["lowest"]), rtol=1e-6)


def test_project_without_the_recorded_level_builds_splines_not_instances(level, tmp_path):
    _multitool_project(tmp_path / "mt", level)
    proj = read_project(tmp_path / "mt")
    out, _, _ = proj.to_level()
    assert out.counts["splines"] == 2 and out.counts["spline_segments"] == 5 and out.counts["instances"] == 0
    assert any(n.startswith("Instances.json: 3 instances read but not written") for n in proj.notes)
    assert any(n.startswith("Models.json: 2 models read and checked, not encoded") for n in proj.notes)
    spl = [struct.unpack_from("<6f4i", out.raw, out.offsets["splines"] + 40 * i) for i in range(2)]
    assert [s[6:] for s in spl] == [(0, 2, 0, -1), (0, 3, 2, -1)]  # Unknown1 0, count, first, Unknown2 -1
    segs = [_segment_by_the_facts(out.raw, out.offsets["spline_segments"] + 128 * i) for i in range(5)]
    assert [s["links"] for s in segs] == [(-1, 1, 0), (0, -1, 0), (-1, 3, 1), (2, 4, 1), (3, -1, 1)]
    assert all(s["u32"] == SEGMENT_UNKNOWN32 for s in segs)
    np.testing.assert_allclose(segs[3]["before"], segs[2]["length"], rtol=1e-6)
    # two runs give the same bytes
    assert read_project(tmp_path / "mt").to_level()[0].to_bytes() == out.to_bytes()


# ----------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("name,edit,field", [
    ("Instances.json", lambda d: d["Instances"][0].update(Location=[1.0, 2.0]), "Location"),
    ("Instances.json", lambda d: d["Instances"][0].pop("Rotation"), "Rotation"),
    ("Instances.json", lambda d: d["Instances"][1].update(ModelID="1"), "ModelID"),
    ("Instances.json", lambda d: d["Instances"][1].update(Hash=2**31), "Hash"),
    ("Instances.json", lambda d: d["Instances"][1].update(Visable=1), "Visable"),
    ("Instances.json", lambda d: d["Instances"][0]["Sounds"]["ExternalSounds"][0].update(U5="loud"), "U5"),
    ("Instances.json", lambda d: d["Instances"][1].update(CollsionModelPaths=[3]), "CollsionModelPaths"),
    ("Instances.json", lambda d: d.update(Instances=5), "Instances"),
    ("Splines.json", lambda d: d["Splines"][0].update(Segments=[]), "Segments"),
    ("Splines.json", lambda d: d["Splines"][0]["Segments"][0].update(Points=[[0, 0, 0]] * 3), "Points"),
    ("Splines.json", lambda d: d["Splines"][1]["Segments"][0]["Points"][1].__setitem__(2, "Infinity"), "Points"),
    ("Splines.json", lambda d: d["Splines"][1]["Segments"][0]["Points"][1].__setitem__(2, "x"), "Points"),
    ("Splines.json", lambda d: d["Splines"][0].update(SplineStyle=1.5), "SplineStyle"),
    ("Models.json", lambda d: d["Models"][0]["ModelObjects"][0].pop("MeshData"), "MeshData"),
    ("Models.json", lambda d: d["Models"][1]["ModelObjects"][0]["Animation"].update(U1=1e39), "U1"),
    ("Models.json", lambda d: d["Models"][0].update(ModelObjects={"a": 1}), "ModelObjects"),
])
def test_bad_fields_name_the_file_and_the_field(level, tmp_path, name, edit, field):
    docs = _multitool_project(tmp_path / "mt", level)
    doc = docs[name]
    edit(doc)
    (tmp_path / "mt" / name).write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=name) as e:
        read_project(tmp_path / "mt").to_level()  # refused on reading, or where a record must be built
    assert e.value.field == field


def test_recorded_level_refuses_count_changes_and_missing_models(tmp_path):
    pbd, lv = _level_with_objects()
    write_project(tmp_path / "p", pbd)
    path = tmp_path / "p" / "Instances.json"
    doc = json.loads(path.read_text())
    good = json.dumps(doc)
    doc["Instances"].pop()
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="2 instances, but PisteLevel.pbd holds 3") as e:
        read_project(tmp_path / "p").to_level()
    assert e.value.field == "Instances" and "Instances.json" in str(e.value)
    doc = json.loads(good)
    doc["Instances"][0]["ModelID"] = 2
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="ModelID 2 is not one of the level's 2 models"):
        read_project(tmp_path / "p").to_level()
    doc = json.loads(good)
    doc["Instances"][1]["Rotation"] = [0.0, "NaN", 0.0, 1.0]  # read, but no matrix can be built of it
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="instance 1: Rotation must be finite") as e:
        read_project(tmp_path / "p").to_level()
    assert e.value.field == "Rotation"
    path.write_text(good)
    spath = tmp_path / "p" / "Splines.json"
    sdoc = json.loads(spath.read_text())
    sdoc["Splines"][0]["Segments"].pop()
    spath.write_text(json.dumps(sdoc))
    with pytest.raises(FormatError, match="spline 0: 1 segments, but PisteLevel.pbd holds 2") as e:
        read_project(tmp_path / "p").to_level()
    assert e.value.field == "Segments"


def test_files_that_are_links_are_refused(level, tmp_path):
    import os

    _multitool_project(tmp_path / "mt", level)
    (tmp_path / "secret.json").write_text(json.dumps({"Splines": [_spline(0)]}))
    (tmp_path / "mt" / "Splines.json").unlink()
    os.symlink(tmp_path / "secret.json", tmp_path / "mt" / "Splines.json")
    with pytest.raises(FormatError, match="Splines.json"):
        read_project(tmp_path / "mt")


# ----------------------------------------------------------------------------- the CLI
def test_cli_convert_edit_import(tmp_path, capsys):
    from piste.cli import main

    pbd, lv = _level_with_objects()
    src = tmp_path / "L.pbd"
    src.write_bytes(pbd.to_bytes())
    assert main(["ssx", "convert", str(src), "--to", "multitool", "--out", str(tmp_path / "mt")]) == 0
    path = tmp_path / "mt" / "Instances.json"
    doc = json.loads(path.read_text())
    doc["Instances"][0]["Location"] = [1.0, 2.0, 3.0]
    path.write_text(json.dumps(doc))
    assert main(["ssx", "import", str(tmp_path / "mt"), "--out", str(tmp_path / "o" / "B.pbd")]) == 0
    out = read_pbd(tmp_path / "o" / "B.pbd")
    rec = np.frombuffer(out.raw, INSTANCE_DTYPE, count=3, offset=out.offsets["instances"])
    np.testing.assert_array_equal(rec["matrix"][0, 3, :3], [1.0, 2.0, 3.0])
    old = np.frombuffer(pbd.raw, INSTANCE_DTYPE, count=3, offset=pbd.offsets["instances"])
    assert rec[1:].tobytes() == old[1:].tobytes()
    # and a project the Multitool wrote, without piste's record: splines built, instances named
    (tmp_path / "mt" / "PisteLevel.json").unlink()
    capsys.readouterr()
    assert main(["ssx", "import", str(tmp_path / "mt"), "--out", str(tmp_path / "q" / "Q.pbd")]) == 0
    err = capsys.readouterr().err
    assert "Instances.json: 3 instances read but not written" in err
    q = read_pbd(tmp_path / "q" / "Q.pbd")
    assert q.counts["splines"] == 2 and q.counts["spline_segments"] == 3 and q.counts["instances"] == 0
    segs = np.frombuffer(q.raw, SEGMENT_DTYPE, count=3, offset=q.offsets["spline_segments"])
    old = np.frombuffer(pbd.raw, SEGMENT_DTYPE, count=3, offset=pbd.offsets["spline_segments"])
    np.testing.assert_allclose(segs["power"], old["power"], rtol=1e-5, atol=0.05)


def test_a_levels_own_nan_spline_point_comes_back(tmp_path):
    pbd, lv = _level_with_objects()
    raw = bytearray(pbd.raw)
    struct.pack_into("<f", raw, pbd.offsets["spline_segments"] + 128 * 2 + 4, float("nan"))  # P3.y, segment 2
    pbd = parse_pbd(bytes(raw))
    write_project(tmp_path / "p", pbd)
    out, _, _ = read_project(tmp_path / "p").to_level()
    assert out.to_bytes() == pbd.to_bytes()
    (tmp_path / "p" / "PisteLevel.json").unlink()  # no recorded level: the segment cannot be built
    with pytest.raises(FormatError, match="spline 1: segment 0: Points must be finite") as e:
        read_project(tmp_path / "p").to_level()
    assert e.value.field == "Points" and "Splines.json" in str(e.value)


def test_a_levels_own_nan_placement_comes_back(tmp_path):
    """A .pbd instance matrix holding NaN: exported as "NaN", read back, its record kept as stored."""
    pbd, lv = _level_with_objects()
    raw = bytearray(pbd.raw)
    struct.pack_into("<f", raw, pbd.offsets["instances"] + 256 + 4 * 13, float("nan"))  # M42 of instance 1
    pbd = parse_pbd(bytes(raw))
    write_project(tmp_path / "p", pbd)
    assert "NaN" in json.loads((tmp_path / "p" / "Instances.json").read_text())["Instances"][1]["Location"]
    out, _, _ = read_project(tmp_path / "p").to_level()
    assert out.to_bytes() == pbd.to_bytes()


def test_hash_section_helper_still_builds_light_lists():
    """The light-only hash section (no instance list) gives instances hash 0 on export."""
    lv = make_level(rows=1, cols=2, seed=1)
    inst = np.zeros(1, INSTANCE_DTYPE)
    inst["matrix"] = np.eye(4)
    p = parse_pbd(pbd_bytes(lv.pbd.records, 3, 1, {"instances": (1, inst.tobytes()), "models": (1, bytes(16)),
                                                   "hash": (None, hash_section_bytes([]))}))
    from piste.formats.ssx.multitool_objects import instances_from_pbd

    d = instances_from_pbd(p).items[0]
    assert d["Hash"] == 0 and d["Location"] == [0.0, 0.0, 0.0] and d["Rotation"] == [0.0, 0.0, 0.0, 1.0]
    assert d["Scale"] == [1.0, 1.0, 1.0]
