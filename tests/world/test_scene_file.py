"""The scene description: parsing, defaults, and errors naming the file, the line and the key."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from piste.errors import ConfigError
from piste.lighting.lights import DirectionalLight, SpotLight
from piste.world.scene_file import SceneError, key_lines, load_scene, loads_scene

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "scenes"


def _err(text, tmp_path, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scene(p)
    return info.value


def test_defaults_of_an_empty_scene(tmp_path):
    p = tmp_path / "empty.toml"
    p.write_text("")
    s = load_scene(p)
    assert s.name == "empty" and s.terrain.kind == "default" and s.terrain.path is None
    assert s.lightmap.res == 8 and s.lod.near == 60.0 and s.visibility.cell == 50.0
    assert s.riders == [] and s.objects == [] and s.lights == () and s.cameras == []
    assert s.source_files() == [p.resolve()]


def test_every_example_parses():
    files = sorted(EXAMPLES.glob("*.toml"))
    assert len(files) >= 3
    for f in files:
        s = load_scene(f)
        assert s.name
        for path in s.source_files():
            assert path.exists(), path


def test_full_scene_values(tmp_path):
    (tmp_path / "l.gltf").write_text('{"asset": {"version": "2.0"}}')
    (tmp_path / "net.bpt").write_text("1\n3 3\n" + "0 0 0\n" * 16)
    s = loads_scene("""
name = "x"
[terrain]
source = "net.bpt"
[lightmap]
res = 16
shadows = false
[lod]
near = 10
far = 20.5
[visibility]
cell = 25
eye_heights = [2]
method = "rays"
[render]
size = [320, 240]
lightmap_mode = "ps2"
[[gltf]]
file = "l.gltf"
scale = 0.01
up = "z"
[[riders]]
position = [1, 2, 3]
heading = 90
clip = "grab"
[[objects]]
model = "builtin:rock"
position = [5, 6]
[[lights]]
type = "spot"
position = [0, 0, 10]
direction = [0, 0, -1]
inner_angle = 5
outer_angle = 10
range = inf
[[cameras]]
name = "c"
eye = [0, 0, 1]
target = [1, 0, 1]
""", tmp_path / "x.toml")
    assert s.terrain.kind == "bpt" and s.terrain.path == (tmp_path / "net.bpt").resolve()
    assert (s.lightmap.res, s.lightmap.shadows) == (16, False)
    assert (s.lod.near, s.lod.far) == (10.0, 20.5)
    assert s.visibility.eye_heights == (2.0,) and s.visibility.method == "rays"
    assert s.render.size == (320, 240) and s.render.lightmap_mode == "ps2"
    assert s.gltf[0].scale == 0.01 and s.gltf[0].up == "z"
    assert s.riders[0].model == "builtin:rider" and s.riders[0].position == (1.0, 2.0, 3.0) and s.riders[0].heading == 90
    assert s.objects[0].builtin == "rock"
    assert isinstance(s.lights[0], SpotLight) and math.isinf(s.lights[0].range)
    assert s.cameras[0].eye == (0.0, 0.0, 1.0)


@pytest.mark.parametrize("text, line, key, what", [
    ('name = "a"\ncolour = 3\n', 2, "colour", "unknown key"),
    ('[terrain]\nseed = 0\nsede = 1\n', 3, "terrain.sede", "unknown key"),
    ('[terrain]\nseed = "zero"\n', 2, "terrain.seed", "expected an integer"),
    ('[lightmap]\nres = 8.5\n', 2, "lightmap.res", "expected an integer"),
    ('[lightmap]\nres = 1\n', 2, "lightmap.res", "2 <= res"),
    ('[[riders]]\nposition = [1, 2]\n\n[[riders]]\nposition = [1, 2]\nclip = 3\n', 6, "riders[1].clip", "expected a string"),
    ('[[riders]]\nposition = [1, 2,\n  3, 4]\nclip = "x"\n', 2, "riders[0].position", "2 or 3 numbers"),
    ('[[objects]]\nposition = [1, 2]\n', 1, "objects[0].model", "missing key"),
    ('[[objects]]\nmodel = "builtin:castle"\nposition = [1, 2]\n', 2, "objects[0].model", "unknown built-in"),
    ('[[objects]]\nmodel = "tree.gltf"\nposition = [1, 2]\n', 2, "objects[0].model", "no such file"),
    ('[[lights]]\ntype = "laser"\n', 2, "lights[0].type", "unknown light type"),
    ('[[lights]]\ntype = "point"\nposition = [0, 0, 1]\nrange = -1\n', 4, "lights[0].range", "range > 0"),
    ('[[lights]]\ntype = "directional"\n', 1, "lights[0].direction", "needs"),
    ('[[lights]]\ntype = "ambient"\nbrightness = 2\n', 3, "lights[0].brightness", "unknown key"),
    ('[[cameras]]\nname = "a"\neye = [0, 0, 1]\n', 1, "cameras[0].target", "needs eye and target"),
    ('[[cameras]]\neye = [0, 0, 1]\ntarget = [0, 1, 1]\nfov = 200\n', 4, "cameras[0].fov", "fov"),
    ('[terrain]\nsource = "h.png"\n', 2, "terrain.source", "no such file"),
    ('[render]\nsize = [10, 10]\n', 2, "render.size", "16..8192"),
    ('[visibility]\nmethod = "magic"\n', 2, "visibility.method", "horizon"),
    ('terrain = 3\n', 1, "terrain", "expected a table"),
])
def test_errors_name_file_line_and_key(tmp_path, text, line, key, what):
    e = _err(text, tmp_path)
    assert isinstance(e, SceneError)
    assert e.line == line and e.key == key, str(e)
    assert what in str(e)
    assert str(e).startswith(f"{tmp_path / 's.toml'}, line {line}, key {key!r}")


def test_toml_syntax_error_has_a_line(tmp_path):
    e = _err('name = "a"\n[terrain\n', tmp_path)
    assert e.line == 2 and "not valid TOML" in str(e)


def test_missing_scene_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_scene(tmp_path / "nope.toml")


def test_height_field_image_needs_spacing(tmp_path):
    import numpy as np
    from PIL import Image

    Image.fromarray(np.zeros((9, 9), np.uint16)).save(tmp_path / "h.png")
    e = _err('[terrain]\nsource = "h.png"\n', tmp_path)
    assert e.key == "terrain.spacing"
    (tmp_path / "ok.toml").write_text('[terrain]\nsource = "h.png"\nspacing = [2, 3]\n')
    s = load_scene(tmp_path / "ok.toml")
    assert s.terrain.kind == "heightfield" and s.terrain.spacing == (2.0, 3.0)


def test_duplicate_names(tmp_path):
    e = _err('[[objects]]\nname = "a"\nmodel = "builtin:tree"\nposition = [1, 2]\n'
             '[[objects]]\nname = "a"\nmodel = "builtin:tree"\nposition = [1, 2]\n', tmp_path)
    assert e.line == 6 and "duplicate" in str(e)


def test_key_lines_skips_multiline_values():
    text = 'a = """\nb = 1\n"""\n[t]\nx = [\n  1,\n  2]\ny = 2\n[[r]]\nz = 1\n[[r]]\nz = {p = 1}\n'
    lines = key_lines(text)
    assert lines[("a",)] == 1 and ("b",) not in lines
    assert lines[("t", "x")] == 5 and lines[("t", "y")] == 8
    assert lines[("r", 0, "z")] == 10 and lines[("r", 1, "z")] == 12


def test_inline_lights_are_piste_lights(tmp_path):
    s = loads_scene('[[lights]]\ntype = "directional"\ndirection = [0, 3, -4]\nintensity = 2\n', tmp_path / "l.toml")
    assert isinstance(s.lights[0], DirectionalLight)
    assert s.lights[0].direction == pytest.approx((0.0, 0.6, -0.8)) and s.lights[0].intensity == 2.0
