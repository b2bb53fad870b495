"""Fuzz SSX Multitool projects (Patches.json, Instances.json, Splines.json, Models.json, Textures/,
Lightmaps/): a project written by piste's
own write_project from a synthetic level (no retail data) in a session fixture, then Patches.json
mutated byte-wise and structurally (fields of the wrong type, huge values, hostile TexturePath
names: ``..``, absolute paths, devices), its PNGs mutated byte-wise, and files swapped for links
leaving the folder; piste's record of the source level (PisteLevel.pbd / .json) mutated byte-wise.
Read with read_project and turned into a level (Project.to_level).  Each case
loads or raises a PisteError naming the project's file, under a time and a memory cap (fuzzlib)."""

from __future__ import annotations

import json
import os
import shutil
import struct

import numpy as np

import pytest
from fuzzlib import HOSTILE, byte_mutations, check, doc_mutations, dump_json, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.errors import FormatError

ssx = pytest.importorskip("piste.formats.ssx")
from piste.formats.ssx import parse_pbd  # noqa: E402
from piste.formats.ssx.multitool import read_project, write_project  # noqa: E402
from piste.formats.ssx.multitool_objects import (  # noqa: E402
    INSTANCE_DTYPE, SPLINE_DTYPE, compose_rows, models_from_json, segment_records,
)
from piste.formats.ssx.synth import pbd_bytes  # noqa: E402
from piste.pipeline.ssx_synth import make_level  # noqa: E402


def _level_with_objects(level):
    """The level with 2 instances of 2 models, a spline of 2 segments, their hashes (piste's own
    encoder: made-up values in the records' documented layout), and a Models.json of 2 models."""
    rng = np.random.default_rng(4)
    inst = np.zeros(2, INSTANCE_DTYPE)
    inst["matrix"] = compose_rows(rng.uniform(-1e3, 1e3, (2, 3)), [[0, 0, 0.6, 0.8], [0, 0, 0, 1]], [[1, 2, 1]] * 2)
    inst["light_colour"] = rng.uniform(0, 1, (2, 4, 4))
    inst["model_id"] = inst["model_id2"] = [0, 1]
    inst["lowest"], inst["highest"] = -10.0, 10.0
    seg = segment_records(rng.uniform(-1e3, 1e3, (2, 4, 3)), 0, 0)
    spl = np.zeros(1, SPLINE_DTYPE)
    spl[0] = (seg["lowest"].min(0), seg["highest"].max(0), 0, 2, 0, -1)
    head = 52
    hashes = struct.pack("<13I", head + 16, 0, head, 2, head, 0, head + 16, 0, head + 16, 0, head + 16, 0,
                         head + 16) + struct.pack("<4i", -5, 1, 8, 0)
    sec = {"instances": (2, inst.tobytes()), "splines": (1, spl.tobytes()), "spline_segments": (2, seg.tobytes()),
           "models": (2, bytes(32)), "hash": (None, hashes)}
    models = {"Models": [{"ModelName": f"m{i}", "Unknown3": 1, "AnimTime": 0.5, "ModelObjects": [
        {"ObjectName": "o", "ParentID": -1, "Flags": 3, "Animation": {
            "U1": 1.0, "U2": 0.0, "U3": 0.0, "U4": 0.0, "U5": 0.0, "U6": 0.0, "AnimationAction": 1,
            "AnimationEntries": [{"AnimationMaths": [{f"Value{v}": 0.5 * v for v in range(1, 7)}]}]},
         "MeshData": [{"MeshPath": f"{i}.obj", "MaterialID": 0}], "Position": [0.0, 0.0, 1.0],
         "Rotation": [0.0, 0.0, 0.0, 1.0], "Scale": [1.0, 1.0, 1.0], "IncludeAnimation": True,
         "IncludeMatrix": True}]} for i in range(2)]}
    return parse_pbd(pbd_bytes(level.pbd.records, 2, 1, sec)), models_from_json(models, "Models.json")


@pytest.fixture(scope="session")
def project(tmp_path_factory):
    d = tmp_path_factory.mktemp("multitool") / "proj"
    level = make_level(rows=2, cols=2, seed=3, n_textures=2)
    pbd, models = _level_with_objects(level)
    write_project(d, pbd, level.textures, level.lightmaps, models=models)
    return d


def _copy(project, tmp_path_factory):
    d = tmp_path_factory.mktemp("m") / "proj"
    shutil.copytree(project, d)
    return d


def _load(path):
    read_project(path).to_level()


def test_seed_loads(project):
    assert check(_load, project / "Patches.json", "multitool seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(20)
def test_patches_bytes(project, tmp_path_factory, data):
    d = _copy(project, tmp_path_factory)
    (d / "Patches.json").write_bytes(data.draw(byte_mutations((project / "Patches.json").read_bytes())))
    check(_load, d / "Patches.json", "multitool json byte-wise", names="proj")


@given(data=st.data())
@fuzz_settings(40)
def test_patches_structure(project, tmp_path_factory, data):
    d = _copy(project, tmp_path_factory)
    doc = json.loads((project / "Patches.json").read_text())
    (d / "Patches.json").write_bytes(dump_json(data.draw(doc_mutations(doc))))
    check(_load, d / "Patches.json", "multitool json structural", names="proj")


OBJECT_FILES = st.sampled_from(["Instances.json", "Splines.json", "Models.json"])


@given(data=st.data())
@fuzz_settings(30)
def test_object_files_structure(project, tmp_path_factory, data):
    """Instances.json, Splines.json, Models.json mutated structurally (the recorded level kept: edits
    are written in place, counts checked) and without the recorded level (splines built)."""
    d = _copy(project, tmp_path_factory)
    name = data.draw(OBJECT_FILES)
    doc = json.loads((project / name).read_text())
    (d / name).write_bytes(dump_json(data.draw(doc_mutations(doc))))
    if data.draw(st.booleans()):
        (d / "PisteLevel.json").unlink()
    check(lambda _: _load(d), d / name, "multitool objects structural")


@given(data=st.data())
@fuzz_settings(20)
def test_object_files_bytes(project, tmp_path_factory, data):
    d = _copy(project, tmp_path_factory)
    name = data.draw(OBJECT_FILES)
    (d / name).write_bytes(data.draw(byte_mutations((project / name).read_bytes())))
    check(lambda _: _load(d), d / name, "multitool objects byte-wise")


@given(data=st.data())
@fuzz_settings(25)
def test_convert_of_a_mutated_level(project, tmp_path_factory, data):
    """A level with instances and splines mutated byte-wise, converted (write_project decodes its
    instance, spline and segment records and the hash section's instance list): a project, or a
    PisteError naming the level."""
    from piste.formats.ssx import read_pbd

    d = tmp_path_factory.mktemp("c")
    src = d / "L.pbd"
    src.write_bytes(data.draw(byte_mutations((project / "PisteLevel.pbd").read_bytes())))
    check(lambda p: write_project(d / "out", read_pbd(p)), src, "multitool convert byte-wise")


PATHS = st.sampled_from([p for p in HOSTILE if isinstance(p, str)] + [
    "../0000.png", "..\\0000.png", "/etc/passwd", "Textures/0000.png", "0000.png/..", "..png", "0000.PNG",
    "99999999999999999999.png", "-1.png", "65536.png", "32768.png", "0001.png", "x.png", "\x00.png", "CON.png"])


@given(data=st.data())
@fuzz_settings(25)
def test_texture_paths(project, tmp_path_factory, data):
    """TexturePath / LightmapID of some patches set to hostile names and numbers."""
    d = _copy(project, tmp_path_factory)
    doc = json.loads((project / "Patches.json").read_text())
    for _ in range(data.draw(st.integers(1, 3))):
        p = doc["Patches"][data.draw(st.integers(0, len(doc["Patches"]) - 1))]
        if data.draw(st.booleans()):
            p["TexturePath"] = data.draw(PATHS)
        else:
            p["LightmapID"] = data.draw(st.sampled_from([-1, 2**15, 2**31, 2**64, 1e308, "0", None, 999]))
    (d / "Patches.json").write_text(json.dumps(doc))
    check(_load, d / "Patches.json", "multitool TexturePath", names="proj")


@given(data=st.data())
@fuzz_settings(20)
def test_images_bytes(project, tmp_path_factory, data):
    """A texture or light-map PNG mutated byte-wise."""
    d = _copy(project, tmp_path_factory)
    images = sorted(str(p.relative_to(d)) for p in d.rglob("*.png"))
    rel = data.draw(st.sampled_from(images))
    (d / rel).write_bytes(data.draw(byte_mutations((d / rel).read_bytes())))
    check(_load, d / "Patches.json", "multitool png byte-wise", names="proj")


@given(data=st.data())
@fuzz_settings(20)
def test_record_bytes(project, tmp_path_factory, data):
    """piste's record of the source level (PisteLevel.pbd / PisteLevel.json) mutated byte-wise: the
    project loads or the refusal names the record."""
    d = _copy(project, tmp_path_factory)
    rel = data.draw(st.sampled_from(["PisteLevel.pbd", "PisteLevel.json"]))
    (d / rel).write_bytes(data.draw(byte_mutations((project / rel).read_bytes())))
    check(lambda _: _load(d), d / rel, "multitool record byte-wise", names="PisteLevel")


@pytest.mark.parametrize("target", ["/etc/hostname", "/dev/zero", "../Patches.json", "missing.png"])
@pytest.mark.parametrize("where", ["Textures/0000.png", "Lightmaps/0000.png"])
def test_image_links_leaving_the_folder(project, tmp_path_factory, target, where):
    """A texture or light-map file that is a link out of its folder (or dangling) is refused."""
    d = _copy(project, tmp_path_factory)
    (d / where).unlink()
    os.symlink(target, d / where)
    assert check(_load, d / "Patches.json", "multitool links", names="proj") == "refused"


def test_json_that_is_a_device_is_refused(project, tmp_path_factory):
    d = _copy(project, tmp_path_factory)
    (d / "Patches.json").unlink()
    os.symlink("/dev/zero", d / "Patches.json")
    assert check(_load, d / "Patches.json", "multitool links", names="Patches.json") == "refused"


# ------------------------------------------------------------------------------ regressions (findings)
@pytest.mark.parametrize("key,value,field", [
    ("LightmapID", 32768, "LightmapID"),  # was OverflowError: out of bounds for int16
    ("LightmapID", -1, "LightmapID"),
    ("LightmapID", 2**64, "LightmapID"),  # was OverflowError: too large to convert to C long
    ("SurfaceType", -(10**9), "SurfaceType"),  # was OverflowError: out of bounds for uint32
    ("LightmapID", 1e308, "LightmapID"),
    ("TexturePath", "99999999999999999999.png", "TexturePath"),  # was OverflowError
    ("TexturePath", "../0000.png", "TexturePath"),
])
def test_out_of_range_fields_name_the_field(project, tmp_path_factory, key, value, field):
    d = _copy(project, tmp_path_factory)
    doc = json.loads((project / "Patches.json").read_text())
    doc["Patches"][1][key] = value
    (d / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="Patches.json") as e:
        read_project(d)
    assert e.value.field == field


@pytest.mark.parametrize("name,where,field", [
    ("Splines.json", ("Splines", 0, "Segments", 1, "Points", 3), 0),  # was TypeError: isfinite of a huge int
    ("Instances.json", ("Instances", 1), "U0"),
    ("Models.json", ("Models", 0), "AnimTime"),
])
@pytest.mark.parametrize("value", [10**40, -(10**39), 10**400])
def test_huge_numbers_in_object_files_name_the_field(project, tmp_path_factory, name, where, field, value):
    d = _copy(project, tmp_path_factory)
    doc = json.loads((project / name).read_text())
    obj = doc
    for k in where:
        obj = obj[k]
    obj[field] = value  # past float32's range (and int64's)
    (d / name).write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=name):
        read_project(d)


def test_deeply_nested_patches_json_is_refused(project, tmp_path_factory):
    d = _copy(project, tmp_path_factory)
    (d / "Patches.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(FormatError, match="Patches.json"):
        read_project(d)


@pytest.mark.parametrize("folder,name", [("Textures", "99999999999.png"), ("Lightmaps", "999999.png")])
def test_numbers_in_image_names_are_never_indices(project, tmp_path_factory, folder, name):
    """The number in a file name is not an index (the Multitool's rule): a light-map page named
    999999.png is the next page in name order (it once allocated 62 GiB of pages), a texture named
    99999999999.png that no patch refers to is not read at all (it once looped 10^11 times)."""
    d = _copy(project, tmp_path_factory)
    shutil.copy(d / folder / "0000.png", d / folder / name)
    proj = read_project(d)
    _, tex, lms = proj.to_level()
    if folder == "Lightmaps":
        assert len(lms) == 2 and len(proj.lightmaps) == 2  # 0000.png, 999999.png
    else:
        assert len(tex) == 2 and name not in proj.texture_files
