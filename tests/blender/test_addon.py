"""The Blender add-on (blender/piste_addon): its pure-Python writers here, and the add-on itself
driven in headless Blender (tests/blender/addon_driver.py) -- installed from the zip ``piste
blender-addon`` writes, a small scene built and exported, built and rendered by piste and compared
with the same scene written by hand, the live preview's reload path, imports of a bundle, an SSX
level and an SSX rider, and the write-back of an edited level.  Two Blender runs in all.

Blender missing: the Blender tests skip, or fail with PISTE_REQUIRE_TOOLS=1."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from piste.cli import main
from piste.pipeline.sources import load_heightfield
from piste.world.scene_file import loads_scene

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "blender"))
from piste_addon import runner, scene_toml, ssx_patches  # noqa: E402  (pure Python: no bpy)

PISTE = Path(sys.executable).parent / "piste"
DRIVER = Path(__file__).with_name("addon_driver.py")

CONFIG = {
    "grid": 33, "spacing": 3.125, "origin": [20.0, 30.0],
    "riders": [{"name": "lead", "position": [50.0, 40.0], "heading": 20.0, "clip": "ride", "phase": 0.0},
               {"name": "second", "position": [56.0, 48.0], "heading": -10.0, "clip": "grab", "phase": 0.4}],
    "camera": {"name": "Overview", "eye": [50.0, 0.0, 40.0], "target": [52.0, 45.0, 8.0], "fov": 50.0,
               "near": 0.5, "far": 2000.0},
    "lights": [{"type": "directional", "name": "Sun", "direction": [-0.4, 0.5, -0.6], "color": [1.0, 0.9, 0.75],
                "intensity": 1.0},
               {"type": "ambient", "name": "Sky", "color": [0.45, 0.55, 0.75], "intensity": 0.35},
               {"type": "point", "name": "Shadow", "position": [50.0, 45.0, 30.0], "color": [1.0, 1.0, 1.0],
                "intensity": -0.6, "range": 30.0}],
    "objects": [{"name": "hut1", "model": "mesh", "position": [44.0, 52.0], "heading": 30.0, "scale": 1.5},
                {"name": "hut2", "model": "mesh", "position": [60.0, 56.0], "heading": -45.0, "scale": 1.0},
                {"name": "tree", "model": "builtin:tree", "position": [40.0, 45.0], "heading": 0.0, "scale": 1.2}],
    "frames": 2, "move_light": "Sun", "edit_dz": 2.0, "edit_du": 0.25,
}


def height(x, y):
    return 0.25 * (100.0 - y) + 4.0 * np.sin(x / 15.0) * np.cos(y / 20.0)  # addon_driver.height


# ----------------------------------------------------------------------------- pure Python
def test_scene_toml_is_what_piste_reads(tmp_path):
    """dumps_scene's TOML loads in piste's scene loader to the same values (tables, arrays of tables,
    an inline bone map, negative intensities, inf); the height-field .npz reads as piste's height field."""
    z = [[float(i * 10 + j) for j in range(9)] for i in range(5)]
    (tmp_path / "hf.npz").write_bytes(scene_toml.heightfield_npz_bytes(z, 2.5, 3.0))
    (tmp_path / "clips.glb").write_bytes(b"")
    scene = {"name": "a \"quoted\" name", "terrain": {"source": "hf.npz", "samples_per_patch": 4},
             "lod": {"preset": "ssx_tricky", "character": [14.0, 35.0]}, "render": {"size": [320, 224], "fog": 0.0},
             "riders": [{"name": "r1", "position": [1.0, 2.0], "heading": 20.0, "clip": "grab", "phase": 0.4}],
             "lights": [{"type": "ambient", "color": [0.5, 0.6, 0.7], "intensity": 0.3},
                        {"type": "point", "position": [1.0, 2.0, 3.0], "intensity": -0.6, "range": math.inf}],
             "objects": [{"name": "o", "model": "builtin:tree", "position": [3.0, 4.0], "scale": 1.5}]}
    text = scene_toml.dumps_scene(scene, "header line")
    assert tomllib.loads(text)["riders"][0]["phase"] == 0.4
    sf = loads_scene(text, tmp_path / "s.toml")
    assert sf.name == 'a "quoted" name' and (sf.lod.near, sf.lod.far) == (30.0, 150.0)
    assert sf.riders[0].clip == "grab" and sf.objects[0].scale == 1.5
    assert [type(L).__name__ for L in sf.lights] == ["AmbientLight", "PointLight"]
    assert sf.lights[1].intensity == -0.6 and math.isinf(sf.lights[1].range)
    hz, spacing = load_heightfield(sf.terrain)
    assert spacing == (2.5, 3.0) and np.array_equal(hz, np.asarray(z))
    with pytest.raises(scene_toml.SceneWriteError, match=r"lights\[0\]\.intensity: expected a number, got NaN"):
        scene_toml.dumps_scene({"lights": [{"type": "ambient", "intensity": float("nan")}]})
    assert scene_toml.write_if_changed(tmp_path / "s.toml", text.encode())
    assert not scene_toml.write_if_changed(tmp_path / "s.toml", text.encode())  # same bytes: not touched


def test_patch_cage_round_trip():
    """A patch's 16 control points become cage vertices in metres and come back as game units; a
    moved point and a moved corner UV are written, untouched patches keep their stored values."""
    pts = [[100.0 * c, 100.0 * r, 5.0 * (r + c)] for r in range(4) for c in range(4)]
    patches = [{"Points": [list(p) for p in pts], "UVPoints": [[0, 0], [1, 0], [0, 1], [1, 1]]} for _ in range(2)]
    verts, faces, uvs = ssx_patches.cage_from_patches(patches)
    assert len(verts) == 32 and len(faces) == 18 and len(uvs) == 72
    assert verts[5] == pytest.approx((1.0, 1.0, 0.1)) and uvs[0] == (0.0, 0.0)
    verts = [tuple(np.float32(v)) for v in verts]  # Blender keeps float32
    verts[16 + 15] = (3.0, 3.0, 1.0)
    corner_uvs = [[(0, 0), (1, 0), (0, 1), (1, 1)], [(0.5, 0), (1, 0), (0, 1), (1, 1)]]
    assert ssx_patches.apply_cage(patches, verts, corner_uvs) == 1
    assert patches[0]["Points"] == pts and patches[1]["Points"][15] == pytest.approx([300.0, 300.0, 100.0])
    assert patches[1]["UVPoints"][0] == [0.5, 0.0]
    with pytest.raises(ValueError, match="vertices were added or deleted"):
        ssx_patches.apply_cage(patches, verts[:-1])


def test_finding_piste(tmp_path, monkeypatch):
    """The preference (an executable or a venv folder), then $PISTE, then PATH; a clear message otherwise."""
    assert runner.find_piste(str(PISTE)) == str(PISTE)
    assert runner.find_piste(str(PISTE.parent.parent)) == str(PISTE)  # the venv
    with pytest.raises(runner.PisteNotFound, match="'piste executable' = .*no executable piste there"):
        runner.find_piste(str(tmp_path / "nowhere"))
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("PISTE", raising=False)
    with pytest.raises(runner.PisteNotFound, match="piste was not found: set Edit > Preferences"):
        runner.find_piste("")
    with pytest.raises(runner.PisteFailed, match="piste ssx info: .*LEVEL.pbd"):
        runner.run_piste(str(PISTE), ["ssx", "info", tmp_path / "LEVEL.pbd"])


def test_addon_zip(tmp_path, capsys):
    """piste blender-addon writes an installable zip (piste_addon/ with bl_info for Blender 3.4+),
    the same bytes twice; a name that is not .zip is a one-line error."""
    out = tmp_path / "a.zip"
    assert main(["blender-addon", "--out", str(out)]) == 0
    with zipfile.ZipFile(out) as zf:
        names = zf.namelist()
        init = zf.read("piste_addon/__init__.py").decode()
    assert {"piste_addon/__init__.py", "piste_addon/exporter.py", "piste_addon/scene_toml.py"} <= set(names)
    assert '"blender": (3, 4, 0)' in init
    first = out.read_bytes()
    assert main(["blender-addon", "--out", str(out)]) == 0 and out.read_bytes() == first
    assert main(["blender-addon", "--out", str(tmp_path / "a.tar")]) == 1
    assert "expected a .zip file name" in capsys.readouterr().err


# ----------------------------------------------------------------------------- in Blender
def _blender() -> str:
    exe = shutil.which("blender")
    if exe is None:
        if os.environ.get("PISTE_REQUIRE_TOOLS") == "1":
            pytest.fail("PISTE_REQUIRE_TOOLS=1 but blender is not installed")
        pytest.skip("blender is not installed")
    return exe


def test_missing_blender_fails_under_require_tools(monkeypatch):
    """Without Blender the Blender tests skip, or fail with PISTE_REQUIRE_TOOLS=1 (CI)."""
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setenv("PISTE_REQUIRE_TOOLS", "1")
    with pytest.raises(pytest.fail.Exception, match="PISTE_REQUIRE_TOOLS=1 but blender is not installed"):
        _blender()
    monkeypatch.setenv("PISTE_REQUIRE_TOOLS", "0")
    with pytest.raises(pytest.skip.Exception):
        _blender()


def _run_blender(exe, cfg: dict, work: Path, name: str) -> dict:
    cfg = dict(cfg, result=str(work / f"{name}.json"))
    path = work / f"{name}_config.json"
    path.write_text(json.dumps(cfg))
    env = dict(os.environ, BLENDER_USER_SCRIPTS=str(work / "blender_scripts"),
               BLENDER_USER_CONFIG=str(work / "blender_config"))  # the user's own Blender is left alone
    r = subprocess.run([exe, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(DRIVER), "--",
                        str(path)], capture_output=True, text=True, timeout=400, env=env)
    result = json.loads(Path(cfg["result"]).read_text()) if Path(cfg["result"]).exists() else None
    if r.returncode != 0 or result is None or result["errors"]:
        raise AssertionError(f"blender ({r.returncode}): {result and result['errors']}\n{r.stdout[-3000:]}\n"
                             f"{r.stderr[-2000:]}")
    return result


def _piste(*args, cwd=None) -> str:
    r = subprocess.run([str(PISTE), *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd)
    assert r.returncode == 0, r.stderr
    return r.stdout + r.stderr


@pytest.fixture(scope="module")
def authored(tmp_path_factory):
    """Blender run 1: the scene built, exported, previewed (headless, 2 frames) and screenshotted."""
    exe = _blender()
    work = tmp_path_factory.mktemp("blender")
    assert main(["blender-addon", "--out", str(work / "piste_addon.zip")]) == 0
    cfg = dict(CONFIG, zip=str(work / "piste_addon.zip"), piste=str(PISTE.parent.parent), out=str(work / "out"),
               steps=["scene", "preview", "screenshot"], screenshot=str(work / "screenshot.png"))
    return work, _run_blender(exe, cfg, work, "run1")


def _hand_written(work: Path, hut: Path) -> Path:
    """The same scene as the Blender one, written by hand (inline lights and camera, an .npz field;
    the huts' model is the one Export wrote, copied)."""
    n, step = CONFIG["grid"], CONFIG["spacing"]
    x = np.arange(n) * step
    z = height(x[None, :], x[:, None])
    folder = work / "hand"
    folder.mkdir()
    shutil.copy(hut, folder / "hut.glb")
    model = "hut.glb"
    np.savez(folder / "field.npz", z=z, dx=np.array([step]), dy=np.array([step]))
    c = CONFIG["camera"]
    lights = [dict(L, intensity=-0.6) if L["type"] == "point" else L for L in CONFIG["lights"]]
    scene = {"name": "hand", "terrain": {"source": "field.npz", "samples_per_patch": 4},
             "lightmap": {"res": 8, "shadows": True}, "lod": {"preset": "ssx_tricky"},
             "visibility": {"cell": 40.0}, "render": {"size": [320, 224], "fog": 0.0},
             "riders": [{k: r[k] for k in ("name", "position", "heading", "clip", "phase")} for r in CONFIG["riders"]],
             "objects": [dict(o, model=model if o["model"] == "mesh" else o["model"]) for o in CONFIG["objects"]],
             "lights": [{k: v for k, v in L.items()} for L in lights],
             "cameras": [{"name": c["name"], "eye": c["eye"], "target": c["target"], "fov": c["fov"],
                          "near": c["near"], "far": c["far"]}]}
    path = folder / "hand.toml"
    path.write_text(scene_toml.dumps_scene(scene))
    return path


def _image(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def test_export_builds_and_renders_like_the_hand_written_scene(authored):
    """Export writes a scene piste builds (terrain from the mesh, 2 riders, the sun and camera through
    glTF, the ambient and the negative light inline); its render matches the hand-written scene's."""
    work, res = authored
    toml = Path(res["toml"])
    text = toml.read_text()
    doc = tomllib.loads(text)
    assert [r["name"] for r in doc["riders"]] == ["lead", "second"]
    assert doc["gltf"][0]["offset"] == [-20.0, -30.0, 0.0] and doc["lod"]["preset"] == "ssx_tricky"
    assert sorted(L["type"] for L in doc["lights"]) == ["ambient", "point"] and doc["lights"][0]["intensity"] < 0
    assert doc["riders"][0]["position"] == pytest.approx([50.0, 40.0]) and doc["riders"][1]["heading"] == pytest.approx(-10.0)
    field = np.load(toml.parent / doc["terrain"]["source"])  # the mesh sampled at its vertices, edges included
    n, step = CONFIG["grid"], CONFIG["spacing"]
    assert field["z"].shape == (n, n) and float(field["dx"][0]) == float(field["dy"][0]) == step
    x = np.arange(n) * step
    assert np.abs(field["z"] - height(x[None, :], x[:, None])).max() < 1e-3
    out = _piste("build", "--quiet", toml)
    assert "2 riders" in out and "3 objects" in out and "3 lights" in out and "Overview" in out
    assert [o["model"] for o in doc["objects"]] == ["assets/Hut.glb", "assets/Hut.glb", "builtin:tree"]
    assert doc["objects"][0]["heading"] == pytest.approx(30.0) and doc["objects"][0]["scale"] == pytest.approx(1.5)
    _piste("render", toml.with_suffix(".piste"), "--camera", "Overview", "--out", work / "exported.png")
    hand = _hand_written(work, toml.parent / "assets" / "Hut.glb")
    _piste("render", hand, "--camera", "Overview", "--out", work / "hand.png")
    a, b = _image(work / "exported.png"), _image(work / "hand.png")
    assert a.shape == b.shape == (224, 320, 3)
    assert a.std() > 10  # a lit, shaded course, not a blank frame
    diff = np.abs(a - b).mean(axis=2)
    print(f"exported vs hand-written render: mean |diff| {diff.mean():.3f}, 99th percentile {np.percentile(diff, 99):.2f} "
          "(0..255)")
    assert diff.mean() < 0.1 and np.percentile(diff, 99) < 2, (diff.mean(), np.percentile(diff, 99))
    shots = os.environ.get("PISTE_BLENDER_SCREENSHOTS")  # the docs' figure: Blender's render | piste's
    if shots:
        Path(shots).mkdir(parents=True, exist_ok=True)
        blender = Image.open(res["screenshot"]).convert("RGB")
        both = Image.new("RGB", (blender.width + 8 + a.shape[1], max(blender.height, a.shape[0])), "white")
        both.paste(blender, (0, 0))
        both.paste(Image.open(work / "exported.png").convert("RGB"), (blender.width + 8, 0))
        both.save(Path(shots) / "blender_and_piste.png", optimize=True)


def test_the_panels_show_the_settings(authored):
    """The sidebar's panels draw (each terrain mode, each object role) with properties that exist and
    operators that are registered, covering the scene's settings and the objects' roles."""
    work, res = authored
    items = set(res["panel_items"])
    assert {"terrain_object", "terrain_file", "seed", "lod_preset", "lightmap_res", "fog_mode", "visibility_band",
            "ambient_intensity"} <= items
    assert {"role", "model", "clip", "phase", "clips_from", "light_kind", "negative", "piste_intensity",
            "piste_range"} <= items
    assert {"piste.export", "piste.preview", "piste.import_file", "piste.ssx_write_back"} <= items


def test_preview_reloads_on_a_change(authored):
    """The preview exports, starts `piste view --headless`, shows frame 0; moving the sun marks the
    scene dirty, the debounced timer re-exports once, the view writes frame 1 (a different image)
    and exits after its 2 frames; the image "piste preview" shows the newest frame."""
    work, res = authored
    assert res["first_frame_loaded"] and res["marked_dirty"] and res["reexports"] == 1
    assert res["view_exit"] == 0 and res["frames"] == ["frame_0000.png", "frame_0001.png"]
    path, size = res["preview_image"]
    assert path.endswith("frame_0001.png") and size == [320, 224]
    f0, f1 = _image(Path(path).with_name("frame_0000.png")), _image(path)
    assert np.abs(f0 - f1).mean() > 1.0  # the moved sun shows
    print(f"change in Blender -> new preview frame: {res['change_to_frame_s']:.2f} s")


@pytest.fixture(scope="module")
def imported(authored):
    """Blender run 2: a bundle, an SSX level (piste's own encoder) and an SSX rider imported, the
    level's cage edited and written back."""
    from piste.pipeline.ssx_synth import make_level

    work, res = authored
    bundle = Path(res["toml"]).with_suffix(".piste")
    if not bundle.exists():
        _piste("build", "--quiet", res["toml"])
    level_dir = work / "level"
    level = make_level(rows=2, cols=3, seed=3).write(level_dir, "LVL")
    _piste("mpf", "encode", work / "rider.mpf")
    cfg = dict(CONFIG, zip=str(work / "piste_addon.zip"), piste=str(PISTE), out=str(work / "imports_out"),
               steps=["import", "writeback", "level_scene"], writeback=str(level_dir / "LVL_edited.pbd"),
               imports={"bundle": str(bundle), "level": str(level), "rider": str(work / "rider.mpf")})
    return work, level, _run_blender(_blender(), cfg, work, "run2")


def test_import_bundle_level_and_rider(imported):
    work, level, res = imported
    imp = res["imports"]
    b = imp["bundle"]
    assert b["meshes"] == ["gltf_Hut0", "gltf_Hut1", "lead:rider", "second:rider", "terrain", "tree2"]
    assert b["armatures"] == 2 and {"terrain material", "objects"} <= set(b["materials"]) and b["images"] >= 1
    for name, o in (("gltf_Hut0", CONFIG["objects"][0]), ("gltf_Hut1", CONFIG["objects"][1])):
        (x, y, z), heading, mesh = b["placed"][name]  # where the artist put them (piste's shifted coordinates)
        assert [x, y] == pytest.approx(o["position"], abs=1e-3) and heading == pytest.approx(o["heading"], abs=1e-3)
        assert z == pytest.approx(float(height(*o["position"])), abs=0.05)
    assert b["placed"]["gltf_Hut0"][2] == b["placed"]["gltf_Hut1"][2]  # instances of one mesh again
    assert b["bounds"][0][:2] == pytest.approx([0.0, 0.0], abs=1e-3)  # piste's coordinates (the shifted course)
    assert b["bounds"][1][:2] == pytest.approx([100.0, 100.0], abs=1e-3)
    lv = imp["level"]
    assert lv["cage_vertices"] == 16 * 6 and lv["images"] >= 2  # textures and light map
    assert len(lv["materials"]) >= 1
    info = _piste("ssx", "info", level)
    lo, hi = [float(v) for v in info.split("bounds (m): [")[1].split("]")[0].split(",")], \
        [float(v) for v in info.split(".. [")[1].split("]")[0].split(",")]
    assert lv["bounds"][0] == pytest.approx(lo, abs=0.01) and lv["bounds"][1] == pytest.approx(hi, abs=0.01)
    assert lv["cage_bounds"][1][2] == pytest.approx(hi[2], abs=0.01)
    r = imp["rider"]
    assert r["armatures"] == 1 and len(r["meshes"]) >= 1 and r["images"] >= 1
    assert 1.0 < r["bounds"][1][1] - r["bounds"][0][1] < 2.5  # a rider's height in metres (glTF Y up)


def test_write_back_edited_level(imported):
    """The highest corner raised 2 m and a corner UV moved in Blender: the written level's bounds
    (piste ssx info) and patch UVs show it; the other patches are as they were."""
    from piste.formats.ssx.pbd import read_pbd

    work, level, res = imported
    wb = res["writeback"]
    assert Path(wb["out"]).exists() and wb["changed"] >= 1 and len(wb["moved"]) >= 1
    before = _piste("ssx", "info", level)
    after = _piste("ssx", "info", wb["out"])
    top = lambda s: float(s.split(".. [")[1].split("]")[0].split(",")[2])  # noqa: E731
    assert top(after) == pytest.approx(top(before) + CONFIG["edit_dz"], abs=0.02)
    old, new = read_pbd(level), read_pbd(wb["out"])
    assert new.uv[0][0][0] == pytest.approx(old.uv[0][0][0] + CONFIG["edit_du"], abs=1e-5)
    touched = {i // 16 for i in wb["moved"]} | {0}
    same = [k for k in range(len(old)) if k not in touched]
    assert np.array_equal(np.asarray(old.control_points)[same], np.asarray(new.control_points)[same])


def _zip_contents(data: bytes) -> dict:
    import io

    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return {n: zf.read(n) for n in zf.namelist()}


def test_the_packaged_zip_matches_the_sources(tmp_path, monkeypatch):
    """The wheel's copy (src/piste/data/blender_addon.zip, package data) holds the add-on as it is in
    blender/ (refresh it with `make blender-addon`), and an install without the sources writes it."""
    from piste.commands import blender_addon

    packaged = blender_addon.PACKAGED_ZIP.read_bytes()
    assert _zip_contents(packaged) == _zip_contents(blender_addon.addon_zip_bytes()), \
        "src/piste/data/blender_addon.zip is stale: run `make blender-addon`"
    monkeypatch.setattr(blender_addon, "_REPO_SOURCES", tmp_path / "no_checkout")
    assert main(["blender-addon", "--out", str(tmp_path / "w.zip")]) == 0
    assert (tmp_path / "w.zip").read_bytes() == packaged
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "data/blender_addon.zip" in pyproject["tool"]["setuptools"]["package-data"]["piste"]


def test_scene_on_an_ssx_level(imported):
    """Terrain 'File' = an SSX level: the .pbd and its .ssh / _L.ssh are copied beside the scene,
    piste's own LOD default (the game's) applies, and piste builds it; a missing file cancels Export."""
    from piste.world.scene_file import load_scene

    work, level, res = imported
    toml = Path(res["level_toml"])
    doc = tomllib.loads(toml.read_text())
    assert doc["terrain"] == {"source": "assets/LVL.pbd"} and "preset" not in doc["lod"]
    assert {p.name for p in (toml.parent / "assets").iterdir()} >= {"LVL.pbd", "LVL.ssh", "LVL_L.ssh"}
    sf = load_scene(toml)
    assert sf.terrain.kind == "ssx_pbd" and (sf.lod.near, sf.lod.far) == (30.0, 150.0)
    assert [L.name for L in sf.lights] == ["World"]  # the ambient from the World colour
    out = _piste("build", "--quiet", toml)
    assert re.search(r"\b6 patches, 1 riders?\b", out), out
    assert "piste export: " in res["missing_terrain"] and "missing.pbd: no such file" in res["missing_terrain"]
