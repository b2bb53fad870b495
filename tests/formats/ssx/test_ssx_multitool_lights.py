"""The Multitool's ``Lights.json`` both ways (issue 22 item 4): ``piste ssx convert --to multitool``
writes a .pbd's 92-byte light records and their hash-section hashes as the Multitool's
``LightJson`` objects, ``piste ssx import`` reads them back into the level; a round trip keeps every
field, a project without ``Lights.json`` keeps today's behaviour.

``_records_by_the_facts`` reads light records with ``struct`` in the field order of SSX-Library's
``PBDHandler.cs`` (u32 Type, u32 SpriteRes, f32, u32, five f32 triples, f32, u32, f32, u32),
independently of piste's LIGHT_DTYPE; levels are written by piste's encoder (synth.pbd_bytes).
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.ssx import parse_pbd, read_pbd
from piste.pipeline.ssx_synth import make_level
from piste.formats.ssx.multitool import read_project, write_project
from piste.formats.ssx.pbd import LIGHT_DTYPE, PATCH_SIZE, hash_section_bytes
from piste.formats.ssx.synth import pbd_bytes

KEYS = ["LightName", "Type", "SpriteRes", "UnknownFloat1", "UnknownInt1", "Colour", "Direction", "Position",
        "LowestXYZ", "HighestXYZ", "UnknownFloat2", "UnknownInt2", "UnknownFloat3", "UnknownInt3", "Hash"]
HASHES = [-1190211347, 5, 2**31 - 1]


def _records_by_the_facts(raw: bytes, offset: int, count: int) -> list:
    out = []
    for i in range(count):
        v = struct.unpack_from("<IIfI3f3f3f3f3ffIfI", raw, offset + 92 * i)
        out.append({"Type": v[0], "SpriteRes": v[1], "UnknownFloat1": v[2], "UnknownInt1": v[3],
                    "Colour": list(v[4:7]), "Direction": list(v[7:10]), "Position": list(v[10:13]),
                    "LowestXYZ": list(v[13:16]), "HighestXYZ": list(v[16:19]), "UnknownFloat2": v[19],
                    "UnknownInt2": v[20], "UnknownFloat3": v[21], "UnknownInt3": v[22]})
    return out


def _lights(k: int) -> np.ndarray:
    rec = np.zeros(k, LIGHT_DTYPE)
    rec["type"] = np.arange(k) % 4
    rec["sprite_res"] = [0, 32, 512][:k] + [16] * max(0, k - 3)
    rec["unknown_float1"] = np.linspace(0.5, 2.0, k)
    rec["unknown_int1"] = 0xFFFFFFFF  # -1 in the Multitool's signed ints
    rec["colour"] = np.linspace(0.1, 3.5, 3 * k).reshape(k, 3)
    rec["direction"] = [0.0, 0.6, -0.8]
    rec["position"] = np.arange(3 * k).reshape(k, 3) * 1234.5 - 9000.25
    rec["lowest"] = rec["position"] - 500.0
    rec["highest"] = rec["position"] + 500.0
    rec["unknown_float2"] = 1.0 / 3.0
    rec["unknown_int2"] = np.arange(k) * 7 + 2**31  # past the signed range
    rec["unknown_float3"] = -0.0
    rec["unknown_int3"] = 17
    return rec


def _level(tmp_path, lights=3, hashes=True):
    """L.pbd (+ .ssh / _L.ssh) with ``lights`` light records, a hash section naming them (when
    ``hashes``) and an instance and mesh data around them."""
    lv = make_level(rows=2, cols=2, seed=2)
    path = lv.write(tmp_path, "L")
    sec = {"instances": (1, bytes(range(256))), "mesh_data": (None, b"\x5a" * 64)}
    if lights:
        sec["lights"] = (lights, _lights(lights).tobytes())
    if hashes:
        sec["hash"] = (None, hash_section_bytes(HASHES[:lights]))
    path.write_bytes(pbd_bytes(lv.pbd.records, 3, 1, sec))
    return path


def _cli(*args) -> None:
    from piste.cli import main

    assert main([str(a) for a in args]) == 0


def test_convert_writes_the_multitools_lights_json(tmp_path):
    src = _level(tmp_path)
    _cli("ssx", "convert", src, "--to", "multitool", "--out", tmp_path / "mt")
    doc = json.loads((tmp_path / "mt" / "Lights.json").read_text())
    assert list(doc) == ["Lights"] and len(doc["Lights"]) == 3
    pbd = read_pbd(src)
    facts = _records_by_the_facts(pbd.raw, pbd.offsets["lights"], 3)
    for i, (d, f) in enumerate(zip(doc["Lights"], facts)):
        assert list(d) == KEYS
        assert d["LightName"] == f"Light_{i}" and d["Hash"] == HASHES[i]
        for k, v in f.items():
            if isinstance(v, int):  # the Multitool's ints are signed 32-bit
                assert d[k] == (v - 2**32 if v >= 2**31 else v), k
            else:
                assert d[k] == v, k
    assert doc["Lights"][0]["UnknownInt1"] == -1 and doc["Lights"][1]["UnknownInt2"] == 7 - 2**31


def test_round_trip_keeps_every_light_byte_and_runs_agree(tmp_path):
    src = _level(tmp_path)
    for k in ("a", "b"):
        _cli("ssx", "convert", src, "--to", "multitool", "--out", tmp_path / f"mt{k}")
        _cli("ssx", "import", tmp_path / f"mt{k}", "--out", tmp_path / k / "B.pbd")
    a, b = (tmp_path / "a" / "B.pbd").read_bytes(), (tmp_path / "b" / "B.pbd").read_bytes()
    assert a == b == src.read_bytes()
    assert (tmp_path / "mta" / "Lights.json").read_bytes() == (tmp_path / "mtb" / "Lights.json").read_bytes()


def test_edited_lights_are_written_in_place(tmp_path):
    src = _level(tmp_path)
    pbd = read_pbd(src)
    write_project(tmp_path / "mt", pbd)
    doc = json.loads((tmp_path / "mt" / "Lights.json").read_text())
    doc["Lights"][1]["Colour"] = [0.25, 0.5, 1.5]
    doc["Lights"][1]["Type"] = 2
    doc["Lights"][2]["Hash"] = -3
    (tmp_path / "mt" / "Lights.json").write_text(json.dumps(doc))
    out, _, _ = read_project(tmp_path / "mt").to_level()
    assert len(out.raw) == len(pbd.raw) and out.counts == pbd.counts
    lo = pbd.offsets["lights"]
    assert out.raw[:lo] == pbd.raw[:lo]
    assert out.raw[lo:lo + 92] == pbd.raw[lo:lo + 92] and out.raw[lo + 184:lo + 276] == pbd.raw[lo + 184:lo + 276]
    got = out.read_lights()
    assert got["type"][1] == 2 and got["colour"][1].tolist() == [0.25, 0.5, 1.5]
    assert out.light_hashes().tolist() == [HASHES[0], HASHES[1], -3]
    hi = pbd.offsets["hash"]
    assert out.raw[lo + 276:hi] == pbd.raw[lo + 276:hi]
    assert out.raw[pbd.offsets["mesh_data"]:] == pbd.raw[pbd.offsets["mesh_data"]:]


def test_a_multitool_project_without_pistes_record_brings_its_lights(tmp_path):
    src = _level(tmp_path)
    pbd = read_pbd(src)
    write_project(tmp_path / "mt", pbd)
    for f in ("PisteLevel.json", "PisteLevel.pbd"):
        (tmp_path / "mt" / f).unlink()
    project = read_project(tmp_path / "mt")
    out, _, _ = project.to_level()
    assert {k: v for k, v in out.counts.items() if v} == {"patches": 4, "textures": 3, "lights": 3}
    assert out.read_lights().tobytes() == pbd.read_lights().tobytes()  # every field
    assert out.light_hashes().tolist() == HASHES
    assert not any("Lights.json" in n for n in project.notes)
    # and back: the same Lights.json
    write_project(tmp_path / "mt2", out)
    assert (tmp_path / "mt2" / "Lights.json").read_bytes() == (tmp_path / "mt" / "Lights.json").read_bytes()


def test_non_finite_floats_are_jsons_strings(tmp_path):
    lv = make_level(rows=1, cols=2, seed=3)
    rec = _lights(1)
    rec["unknown_float2"], rec["colour"][0, 1] = np.nan, -np.inf
    pbd = parse_pbd(pbd_bytes(lv.pbd.records, 1, 1, {"lights": (1, rec.tobytes())}))
    write_project(tmp_path, pbd)
    d = json.loads((tmp_path / "Lights.json").read_text())["Lights"][0]
    assert d["UnknownFloat2"] == "NaN" and d["Colour"][1] == "-Infinity" and d["Hash"] == 0
    (tmp_path / "PisteLevel.json").unlink()
    out, _, _ = read_project(tmp_path).to_level()
    got = out.read_lights()
    assert np.isnan(got["unknown_float2"][0]) and got["colour"][0, 1] == -np.inf


def test_without_lights_json_today_s_behaviour(tmp_path):
    src = _level(tmp_path)
    pbd = read_pbd(src)
    write_project(tmp_path / "mt", pbd)
    (tmp_path / "mt" / "Lights.json").unlink()
    out, _, _ = read_project(tmp_path / "mt").to_level()
    assert out.to_bytes() == pbd.to_bytes()  # the recorded level's lights
    for f in ("PisteLevel.json", "PisteLevel.pbd"):
        (tmp_path / "mt" / f).unlink()
    out, _, _ = read_project(tmp_path / "mt").to_level()
    assert {k: v for k, v in out.counts.items() if v} == {"patches": 4, "textures": 3}
    assert out.raw[out.patch_offset + 4 * PATCH_SIZE:] == b""


def test_a_level_without_a_hash_section(tmp_path):
    src = _level(tmp_path, hashes=False)
    pbd = read_pbd(src)
    assert pbd.light_hashes() is None
    write_project(tmp_path / "mt", pbd)
    doc = json.loads((tmp_path / "mt" / "Lights.json").read_text())
    assert [d["Hash"] for d in doc["Lights"]] == [0, 0, 0]
    out, _, _ = read_project(tmp_path / "mt").to_level()
    assert out.to_bytes() == pbd.to_bytes()
    doc["Lights"][0]["Hash"] = 99
    (tmp_path / "mt" / "Lights.json").write_text(json.dumps(doc))
    project = read_project(tmp_path / "mt")
    out, _, _ = project.to_level()
    assert out.to_bytes() == pbd.to_bytes() and "Hash values are not kept" in project.notes[-1]


def test_hash_lists_read_as_the_multitool_lays_them_out(tmp_path):
    """A hash section written by hand from the facts: 13 u32 (total length, then count/offset
    pairs for unknown, instances, unknown, lights, unknown, cameras), an instance list before the
    light list, the light list sorted by hash (not by light)."""
    lv = make_level(rows=1, cols=2, seed=3)
    pairs_inst = struct.pack("<2i", 42, 0)
    pairs_light = struct.pack("<4i", -9, 1, 300, 0)
    head = 52
    li = head + len(pairs_inst)
    end = li + len(pairs_light)
    h = struct.pack("<13I", end, 0, head, 1, head, 0, li, 2, li, 0, end, 0, end) + pairs_inst + pairs_light
    pbd = parse_pbd(pbd_bytes(lv.pbd.records, 1, 1, {"lights": (2, _lights(2).tobytes()), "hash": (None, h)}))
    assert pbd.light_hashes().tolist() == [300, -9]
    assert hash_section_bytes([300, -9])[52:] == struct.pack("<4i", -9, 1, 300, 0)


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["Lights"][0].update(Colour=[1.0, 2.0]), "light 0: Colour must be a list of 3 numbers"),
    (lambda d: d["Lights"][1].update(Type=2**33), "light 1: Type must be a 32-bit integer"),
    (lambda d: d["Lights"][1].update(UnknownFloat1=1e39), "light 1: UnknownFloat1 must be a number"),
    (lambda d: d["Lights"][2].update(Hash="x"), "light 2: Hash must be a 32-bit integer"),
    (lambda d: d.update(Lights=7), "expected a list of lights"),
    (lambda d: d["Lights"].pop(), "2 lights, but PisteLevel.pbd holds 3"),
])
def test_bad_lights_json_is_refused_by_name(tmp_path, edit, words):
    from piste.cli import main

    src = _level(tmp_path)
    _cli("ssx", "convert", src, "--to", "multitool", "--out", tmp_path / "mt")
    doc = json.loads((tmp_path / "mt" / "Lights.json").read_text())
    edit(doc)
    (tmp_path / "mt" / "Lights.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="Lights.json") as e:
        read_project(tmp_path / "mt").to_level()
    assert words in str(e.value)
    assert main(["ssx", "import", str(tmp_path / "mt"), "--out", str(tmp_path / "o" / "B.pbd")]) == 1
    assert not (tmp_path / "o" / "B.pbd").exists()
