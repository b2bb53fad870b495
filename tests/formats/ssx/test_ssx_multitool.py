"""Multitool project (Patches.json + Textures/ + Lightmaps/): the Multitool's conventions both ways,
and faithful, deterministic writes (issue 22 items 3 and 4).

``_multitool_read_lightmaps`` / ``_multitool_write_lightmaps`` are the Multitool's import and export
of light maps written from the fact sheet (SSX-FORMATS.md "Multitool project"), independently of
piste's module: page i is the i-th ``Lightmaps/*.png`` by name, RGB darkened ``(c + 1) // 2`` on
import and brightened ``clamp(2c - 1, 0, 255)`` on export, alpha as stored both ways.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from PIL import Image

from piste.errors import FormatError
from piste.formats.ssx import parse_pbd, read_pbd
from piste.pipeline.ssx_synth import make_level
from piste.formats.ssx.multitool import brighten, darken, export_texture, read_project, write_project
from piste.formats.ssx.pbd import LIGHT_DTYPE, PATCH_SIZE, hash_section_bytes
from piste.formats.ssx.ssh import SshBank, SshImage, lightmap_bank, lightmap_pages
from piste.formats.ssx.multitool_objects import (
    INSTANCE_DTYPE, SEGMENT_DTYPE, SPLINE_DTYPE, compose_rows, segment_records,
)
from piste.formats.ssx.synth import pbd_bytes


@pytest.fixture(scope="module")
def level():
    return make_level(rows=2, cols=2, seed=4, trick_every=3)


def _multitool_read_lightmaps(folder):
    files = sorted((folder / "Lightmaps").glob("*.png"), key=lambda p: p.name)
    pages = []
    for f in files:
        img = np.asarray(Image.open(f).convert("RGBA")).astype(np.int32)
        img[..., :3] = (img[..., :3] + 1) // 2
        pages.append(img.astype(np.uint8))
    return np.stack(pages)


def _multitool_write_lightmaps(folder, bank):
    (folder / "Lightmaps").mkdir(parents=True, exist_ok=True)
    for im in bank.images:
        img = im.stored_rgba().astype(np.int32)
        img[..., :3] = np.clip(img[..., :3] * 2 - 1, 0, 255)
        Image.fromarray(img.astype(np.uint8), "RGBA").save(folder / "Lightmaps" / f"{im.name}.png")


# ----------------------------------------------------------------------------- the conventions
def test_brighten_and_darken():
    c = np.arange(256, dtype=np.uint8)
    np.testing.assert_array_equal(brighten(c), np.clip(2 * c.astype(int) - 1, 0, 255))
    np.testing.assert_array_equal(darken(c), (c.astype(int) + 1) // 2)
    np.testing.assert_array_equal(darken(brighten(c[:129])), c[:129])  # exact inverses up to 128
    assert int(darken(brighten(np.uint8(200)))) == 128  # above 128 the brightening clamps


def test_light_map_pngs_are_brightened_alpha_as_stored(level, tmp_path):
    write_project(tmp_path, level.pbd, level.textures, level.lightmaps)
    png = np.asarray(Image.open(tmp_path / "Lightmaps" / "0000.png").convert("RGBA")).astype(int)
    stored = lightmap_pages(level.lightmaps)[0].astype(int)
    np.testing.assert_array_equal(png[..., :3], np.clip(2 * stored[..., :3] - 1, 0, 255))
    np.testing.assert_array_equal(png[..., 3], stored[..., 3])
    assert stored[..., 3].max() > 128  # over-bright As kept as stored, not doubled or clamped


def test_textures_always_brightened():
    """RGB brightened even when the stored colours exceed 128 (piste once brightened only when
    RGB <= 128); palette alpha doubled when no entry exceeds 128, else as stored."""
    pal = np.array([[200, 10, 128, 128], [129, 255, 0, 64]], np.uint8)
    im = SshImage("abcd", 2, np.array([[0, 1]], np.uint8), pal)
    out = export_texture(im).astype(int)
    np.testing.assert_array_equal(out[0, :, :3], np.clip(2 * pal[:, :3].astype(int) - 1, 0, 255))
    np.testing.assert_array_equal(out[0, :, 3], [255, 128])
    pal[1, 3] = 200  # an alpha above 128: the palette's alpha is left as stored
    np.testing.assert_array_equal(export_texture(im)[0, :, 3], [128, 200])


def test_piste_project_read_the_multitools_way_gives_the_stored_lightmap_bytes(level, tmp_path):
    write_project(tmp_path, level.pbd, level.textures, level.lightmaps)
    pages = _multitool_read_lightmaps(tmp_path)
    assert lightmap_bank(pages).to_bytes() == level.lightmaps.to_bytes()


def test_multitool_project_read_by_piste_gives_the_stored_lightmap_bytes(level, tmp_path):
    write_project(tmp_path, level.pbd, level.textures)  # patches and textures piste's way
    _multitool_write_lightmaps(tmp_path, level.lightmaps)  # the light maps the Multitool's way
    _, _, lms = read_project(tmp_path).to_level()
    assert lms.to_bytes() == level.lightmaps.to_bytes()


def test_textures_numbered_by_first_appearance(level, tmp_path):
    """A Multitool project (no piste record): texture i is the i-th distinct TexturePath in
    Patches.json order; the number in a name is ignored; unreferenced files are not read."""
    write_project(tmp_path, level.pbd, level.textures, level.lightmaps)
    for f in ("PisteLevel.json", "PisteLevel.pbd"):
        (tmp_path / f).unlink()
    doc = json.loads((tmp_path / "Patches.json").read_text())
    (tmp_path / "Textures" / "0002.png").rename(tmp_path / "Textures" / "snow.png")
    order = ["0001.png", "snow.png", "0001.png", "0000.png"]
    for p, tp in zip(doc["Patches"], order):
        p["TexturePath"] = tp
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    Image.new("RGBA", (4, 4)).save(tmp_path / "Textures" / "9999.png")  # nobody's texture
    proj = read_project(tmp_path)
    assert proj.texture_files == ["0001.png", "snow.png", "0000.png"]
    assert proj.texture_index.tolist() == [0, 1, 0, 2]
    _, tex, _ = proj.to_level()
    assert [im.name for im in tex.images] == ["0000", "0001", "0002"]
    for i, src in enumerate([1, 2, 0]):  # stored colours darkened back exactly
        np.testing.assert_array_equal(tex.images[i].stored_rgba()[..., :3],
                                      level.textures.images[src].stored_rgba()[..., :3])
        np.testing.assert_array_equal(tex.images[i].stored_rgba()[..., 3], 128)


# ----------------------------------------------------------------------------- faithful writes
def _level_with_sections():
    """A level whose other sections hold content (made-up bytes standing in for instances, lights,
    splines, a model and its mesh data; their meaning does not matter here: they must come back
    unchanged)."""
    lv = make_level(rows=2, cols=3, seed=5)
    rng = np.random.default_rng(9)
    inst = np.frombuffer(rng.bytes(3 * 256), INSTANCE_DTYPE).copy()  # every field made up but the placement
    inst["matrix"] = compose_rows(rng.uniform(-1e4, 1e4, (3, 3)), [[0, 0, 0.6, 0.8]] * 3, [[1, 2, 1]] * 3)
    inst["lowest"], inst["highest"] = -50.0, 50.0
    seg = segment_records(rng.uniform(-1e4, 1e4, (2, 4, 3)), 0, 0)
    seg["coefficients"] = rng.uniform(-1, 1, (2, 4))  # not the fit piste would make: must come back as stored
    spl = np.zeros(1, SPLINE_DTYPE)
    spl[0] = ((-1e4,) * 3, (1e4,) * 3, 7, 2, 0, -1)
    sec = {"instances": (3, inst.tobytes()), "lights": (2, _lights(2).tobytes()), "splines": (1, spl.tobytes()),
           "spline_segments": (2, seg.tobytes()), "models": (1, rng.bytes(64)),
           "model_pointers": (None, rng.bytes(16)), "hash": (None, hash_section_bytes([-7, 123456789])),
           "mesh_data": (None, rng.bytes(256))}
    return parse_pbd(pbd_bytes(lv.pbd.records, 3, 1, sec)), lv


def _lights(k: int, seed: int = 3) -> np.ndarray:
    """``k`` light records with every field set (finite floats, integers across the u32 range)."""
    rng = np.random.default_rng(seed)
    rec = np.zeros(k, LIGHT_DTYPE)
    for name in LIGHT_DTYPE.names:
        shape = rec[name].shape
        if rec[name].dtype.kind == "f":
            rec[name] = rng.uniform(-5e3, 5e3, shape).astype(np.float32)
        else:
            rec[name] = rng.integers(0, 2**32, shape, dtype=np.uint64).astype(np.uint32)
    return rec


def _convert_and_import(pbd, lv, tmp_path, name):
    proj = tmp_path / f"{name}_proj"
    write_project(proj, pbd, lv.textures, lv.lightmaps)
    project = read_project(proj)
    out, tex, lms = project.to_level()
    return proj, project, out, tex, lms


def test_round_trip_keeps_every_section_and_field(tmp_path):
    pbd, lv = _level_with_sections()
    _, project, out, tex, lms = _convert_and_import(pbd, lv, tmp_path, "a")
    assert project.notes == []
    assert out.to_bytes() == pbd.to_bytes()  # every section, count and interpreted field
    assert out.counts == pbd.counts and out.counts["instances"] == 3 and out.counts["lights"] == 2
    assert lms.to_bytes() == lv.lightmaps.to_bytes()
    for a, b in zip(tex.images, lv.textures.images):
        np.testing.assert_array_equal(a.stored_rgba(), b.stored_rgba())
    # two runs give identical files and bytes
    p1, _, out1, tex1, _ = _convert_and_import(pbd, lv, tmp_path, "b")
    p2, _, out2, tex2, _ = _convert_and_import(pbd, lv, tmp_path, "c")
    for f in sorted(x.relative_to(p1) for x in p1.rglob("*") if x.is_file()):
        assert (p1 / f).read_bytes() == (p2 / f).read_bytes(), f
    assert out1.to_bytes() == out2.to_bytes() and tex1.to_bytes() == tex2.to_bytes()


def test_edited_project_keeps_the_other_sections(tmp_path):
    pbd, lv = _level_with_sections()
    proj = tmp_path / "p"
    write_project(proj, pbd, lv.textures, lv.lightmaps)
    doc = json.loads((proj / "Patches.json").read_text())
    doc["Patches"][2]["Points"][5][2] += 40.0
    doc["Patches"][4]["SurfaceType"] = 9
    doc["Patches"][1]["TrickOnlyPatch"] = True
    (proj / "Patches.json").write_text(json.dumps(doc))
    out, _, _ = read_project(proj).to_level()
    po, n = pbd.patch_offset, len(pbd)
    assert out.raw[:po] == pbd.raw[:po] and out.raw[po + n * PATCH_SIZE:] == pbd.raw[po + n * PATCH_SIZE:]
    assert out.surface_type[4] == 9 and out.trick_only[1] and not pbd.trick_only[1]
    assert abs(out.control_points[2, 1, 1, 2] - pbd.control_points[2, 1, 1, 2] - 40.0) < 0.05
    same = [k for k in range(n) if k not in (1, 2, 4)]
    assert out.records[same].tobytes() == pbd.records[same].tobytes()


def test_changed_patch_count_gets_the_minimal_default(tmp_path):
    pbd, lv = _level_with_sections()
    proj = tmp_path / "p"
    write_project(proj, pbd, lv.textures, lv.lightmaps)
    doc = json.loads((proj / "Patches.json").read_text())
    del doc["Patches"][-1]
    (proj / "Patches.json").write_text(json.dumps(doc))
    project = read_project(proj)
    out, _, _ = project.to_level()
    assert len(out) == 5 and "6 patches, Patches.json 5" in project.notes[0] and "3 instances" in project.notes[0]
    assert "lights" not in project.notes[0] and "spline" not in project.notes[0]  # from Lights.json, Splines.json
    assert {k: v for k, v in out.counts.items() if v} == {"patches": 5, "textures": 3, "lights": 2, "splines": 1,
                                                          "spline_segments": 2}
    # after the patches: the lights, the splines rebuilt from Splines.json (the Multitool's way), the
    # hash list (each padded to 16 bytes), no filler bytes
    seg = np.frombuffer(pbd.sections["spline_segments"][:256], SEGMENT_DTYPE)
    rebuilt = segment_records(project.splines.points(0), 0, 0)  # the raw points as Splines.json holds them
    spl = np.zeros(1, SPLINE_DTYPE)
    spl[0] = (rebuilt["lowest"].min(0), rebuilt["highest"].max(0), 0, 2, 0, -1)
    tail = out.raw[out.patch_offset + 5 * PATCH_SIZE:]
    assert tail == (pbd.read_lights().tobytes() + b"\0" * 8 + spl.tobytes() + b"\0" * 8 + rebuilt.tobytes()
                    + hash_section_bytes([-7, 123456789]) + b"\0" * 12)
    np.testing.assert_allclose(rebuilt["power"], seg["power"], rtol=1e-6, atol=1e-2)  # the points come back
    assert out.light_hashes().tolist() == [-7, 123456789]


def test_empty_level_invents_nothing(tmp_path, capsys):
    """Issue 22: a level without instances, lights, splines or models through convert + import
    comes back without them and without filler bytes, with or without piste's record; the
    Multitool's other files are named as not read."""
    from piste.cli import main

    lv = make_level(rows=2, cols=2, seed=1)
    src = lv.write(tmp_path, "L")
    for k in ("a", "b"):
        assert main(["ssx", "convert", str(src), "--to", "multitool", "--out", str(tmp_path / f"mt{k}")]) == 0
        assert main(["ssx", "import", str(tmp_path / f"mt{k}"), "--out", str(tmp_path / k / "B.pbd")]) == 0
    a, b = (tmp_path / "a" / "B.pbd").read_bytes(), (tmp_path / "b" / "B.pbd").read_bytes()
    assert a == b == src.read_bytes()
    for f in ("B.ssh", "B_L.ssh"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    # without piste's record (a project as the Multitool writes it): patches + the minimal default
    for f in ("PisteLevel.json", "PisteLevel.pbd"):
        (tmp_path / "mta" / f).unlink()
    (tmp_path / "mta" / "Lights.json").write_text("{}")  # read: no lights
    (tmp_path / "mta" / "Splines.json").write_text("{}")  # read: no splines
    (tmp_path / "mta" / "Cameras.json").write_text("{}")
    capsys.readouterr()
    assert main(["ssx", "import", str(tmp_path / "mta"), "--out", str(tmp_path / "c" / "C.pbd")]) == 0
    err = capsys.readouterr().err
    assert "Cameras.json: not read by piste" in err and "Lights.json" not in err and "Splines.json" not in err
    assert "Instances.json" not in err  # written from a level without instances: {"Instances": []}
    c = read_pbd(tmp_path / "c" / "C.pbd")
    assert {k: v for k, v in c.counts.items() if v} == {"patches": 4, "textures": 3}
    assert c.raw[c.patch_offset + 4 * PATCH_SIZE:] == b""
    np.testing.assert_allclose(c.control_points, lv.pbd.control_points, atol=0.05)
    assert (tmp_path / "c" / "C_L.ssh").read_bytes() == (tmp_path / "L_L.ssh").read_bytes()
    # no Textures/ or Lightmaps/ folder: no bank is written (none is made up)
    import shutil

    shutil.rmtree(tmp_path / "mta" / "Textures")
    shutil.rmtree(tmp_path / "mta" / "Lightmaps")
    assert main(["ssx", "import", str(tmp_path / "mta"), "--out", str(tmp_path / "d" / "D.pbd")]) == 0
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["D.pbd"]


def test_round_trip_of_a_made_level(level, tmp_path):
    write_project(tmp_path, level.pbd, level.textures, level.lightmaps)
    doc = json.loads((tmp_path / "Patches.json").read_text())
    p0 = doc["Patches"][0]
    assert set(p0) == {"PatchName", "LightMapPoint", "UVPoints", "Points", "SurfaceType", "TrickOnlyPatch",
                       "TexturePath", "LightmapID"}
    assert len(p0["Points"]) == 16 and len(p0["UVPoints"]) == 4 and p0["TexturePath"] == "0000.png"
    assert sorted(f.name for f in (tmp_path / "Textures").iterdir()) == ["0000.png", "0001.png", "0002.png"]
    proj = read_project(tmp_path)
    np.testing.assert_array_equal(proj.control_points, level.pbd.control_points)
    np.testing.assert_array_equal(proj.trick_only, level.pbd.trick_only)
    np.testing.assert_array_equal(proj.texture_index, level.pbd.texture_index)
    pbd, tex, lms = proj.to_level()
    assert pbd.to_bytes() == level.pbd.to_bytes()
    assert lms.to_bytes() == level.lightmaps.to_bytes()
    assert struct.unpack_from("<I", pbd.raw, 52)[0] == len(tex) == 3


def test_bad_projects(tmp_path, level):
    with pytest.raises(FormatError, match="no such file"):
        read_project(tmp_path)
    write_project(tmp_path, level.pbd)
    doc = json.loads((tmp_path / "Patches.json").read_text())
    doc["Patches"][1]["TexturePath"] = "../../etc/passwd.png"
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="patch 1: TexturePath"):
        read_project(tmp_path)
    doc["Patches"][1]["TexturePath"] = "0001.png"
    del doc["Patches"][2]["Points"]
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="patch 2: missing key") as e:
        read_project(tmp_path)
    assert e.value.field == "Points"


def test_missing_texture_and_page_are_refused(tmp_path, level):
    write_project(tmp_path, level.pbd, level.textures, level.lightmaps)
    doc = json.loads((tmp_path / "Patches.json").read_text())
    doc["Patches"][3]["LightmapID"] = 1
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="patch 3: LightmapID 1 but Lightmaps/ holds 1 page") as e:
        read_project(tmp_path)
    assert e.value.field == "LightmapID" and "Patches.json" in str(e.value)
    doc["Patches"][3]["LightmapID"] = 0
    doc["Patches"][2]["TexturePath"] = "gone.png"
    (tmp_path / "Patches.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="patch 2: TexturePath 'gone.png': Textures/gone.png does not exist"):
        read_project(tmp_path)


def test_bank_names_become_texture_paths(tmp_path, level):
    """TexturePath is the texture's bank name (the Multitool's export), textures read back by it."""
    bank = SshBank([SshImage(n, im.kind, im.pixels, im.palette, long_name="")
                    for n, im in zip(("snw1", "rck2", "ice3"), level.textures.images)])
    write_project(tmp_path, level.pbd, bank, level.lightmaps)
    doc = json.loads((tmp_path / "Patches.json").read_text())
    assert [p["TexturePath"] for p in doc["Patches"]] == ["snw1.png", "rck2.png", "ice3.png", "snw1.png"]
    pbd, tex, _ = read_project(tmp_path).to_level()
    np.testing.assert_array_equal(pbd.texture_index, level.pbd.texture_index)
    from piste.formats.ssx.ssh import parse_ssh

    assert len(parse_ssh(tex.to_bytes(), "t.ssh")) == 3
