"""The scene file's sections are a registry (piste.world.scene_file.SCENE_SECTIONS): loads_scene walks
it, a registered section is parsed into a typed value, and a section nobody registered is refused
naming the file, the line and the section."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from piste.errors import ConfigError
from piste.world.scene_file import (SCENE_SECTIONS, SceneError, SceneFile, SceneSection, SceneTable, load_scene,
                                    loads_scene, register_section, unregister_section)


@dataclass
class Weather:
    snow: float = 0.0
    wind: tuple = (0.0, 0.0)


def _parse_weather(t: SceneTable, scene: SceneFile) -> Weather:
    t.allow({"snow", "wind"})
    w = Weather(t.get("snow", "float", 0.0), t.get("wind", "vec2", (0.0, 0.0)))
    if not 0.0 <= w.snow <= 1.0:
        raise t.error("snow", f"expected 0 <= snow <= 1, got {w.snow}")
    return w


@pytest.fixture
def weather():
    section = register_section(SceneSection("weather", _parse_weather))
    try:
        yield section
    finally:
        unregister_section("weather")


def test_an_unknown_section_is_refused_naming_file_line_and_section(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('name = "x"\n\n[weather]\nsnow = 0.5\n')
    with pytest.raises(SceneError) as info:
        load_scene(p)
    e = info.value
    assert e.path == str(p) and e.line == 3 and e.key == "weather"
    assert str(e).startswith(f"{p}, line 3, key 'weather': unknown key 'weather': expected one of ")
    for name in SCENE_SECTIONS:  # the message lists what the registry takes
        assert name in str(e)


def test_a_registered_section_is_parsed_into_a_typed_value(tmp_path, weather):
    s = loads_scene('[terrain]\nseed = 3\n\n[weather]\nsnow = 0.5\nwind = [1, 2]\n', tmp_path / "s.toml")
    assert s.sections["weather"] == Weather(0.5, (1.0, 2.0))
    assert s.terrain.seed == 3  # the built-in sections as before
    assert loads_scene("", tmp_path / "e.toml").sections["weather"] == Weather()  # absent: its defaults
    with pytest.raises(SceneError) as info:  # its errors name the file, the line and the key
        loads_scene('name = "x"\n[weather]\nsnow = 2.0\n', tmp_path / "s.toml")
    assert info.value.line == 3 and info.value.key == "weather.snow" and "expected 0 <= snow <= 1" in str(info.value)
    with pytest.raises(SceneError, match="unknown key 'rain'"):
        loads_scene('[weather]\nrain = 1\n', tmp_path / "s.toml")


def test_unregistered_again_the_section_is_refused(tmp_path):
    section = register_section(SceneSection("weather", _parse_weather))
    assert loads_scene("[weather]\nsnow = 0.1\n", tmp_path / "s.toml").sections["weather"].snow == 0.1
    assert unregister_section("weather") is section
    with pytest.raises(SceneError, match="unknown key 'weather'"):
        loads_scene("[weather]\nsnow = 0.1\n", tmp_path / "s.toml")


def test_sections_are_parsed_in_registry_order_and_see_earlier_ones(tmp_path):
    seen = []

    def parse(t: SceneTable, scene: SceneFile) -> str:
        seen.append((scene.terrain.kind, len(scene.riders), list(scene.cameras)))
        return "parsed"

    register_section(SceneSection("early", parse), after="terrain")
    try:
        assert list(SCENE_SECTIONS)[:2] == ["terrain", "early"]
        s = loads_scene('[terrain]\nseed = 1\n[[riders]]\nposition = [0, 0]\n', tmp_path / "s.toml")
        assert s.sections["early"] == "parsed"
        assert seen == [("default", 0, [])]  # after the terrain, before the riders
    finally:
        unregister_section("early")


def test_array_sections_and_cross_section_checks(tmp_path):
    checked = []

    def parse(items: list, scene: SceneFile) -> list:
        return [t.get("n", "int", required=True) for t in items]

    def check(t: SceneTable, scene: SceneFile) -> None:
        checked.append(scene.sections["marks"])
        if len(scene.sections["marks"]) > len(scene.objects):
            raise t.error(None, "more marks than objects")

    register_section(SceneSection("marks", parse, array=True, check=check))
    try:
        text = '[[marks]]\nn = 1\n\n[[objects]]\nmodel = "builtin:tree"\nposition = [0, 0]\n'
        assert loads_scene(text, tmp_path / "s.toml").sections["marks"] == [1]
        with pytest.raises(SceneError) as info:
            loads_scene(text + '[[marks]]\nn = 2\n', tmp_path / "s.toml")
        assert info.value.key == "marks" and "more marks than objects" in str(info.value)
        with pytest.raises(SceneError) as info:
            loads_scene('[[marks]]\nm = 1\n', tmp_path / "s.toml")
        assert info.value.key == "marks[0].n" and info.value.line == 1 and "missing key 'n'" in str(info.value)
    finally:
        unregister_section("marks")
    assert checked


def test_register_refuses_duplicates_reserved_names_and_unknown_places():
    with pytest.raises(ConfigError, match="registered already"):
        register_section(SceneSection("terrain", _parse_weather))
    for reserved in ("name", "allow_paths", "text", "path", "sections"):
        with pytest.raises(ConfigError, match="reserved"):
            register_section(SceneSection(reserved, _parse_weather))
    with pytest.raises(ConfigError, match="no scene section 'sky'"):
        register_section(SceneSection("weather", _parse_weather), after="sky")
    with pytest.raises(ConfigError, match="no scene section 'weather'"):
        unregister_section("weather")
    assert "weather" not in SCENE_SECTIONS


def test_the_built_in_sections_and_their_order():
    assert list(SCENE_SECTIONS) == ["terrain", "lightmap", "lod", "visibility", "render", "pack", "auto_objects",
                                    "tile_objects", "gltf", "riders", "objects", "lights", "cameras"]


def test_a_section_reads_files_and_ranges_through_the_table(tmp_path):
    """SceneTable.file confines a path as every scene path is; SceneTable.bounded checks a range."""

    def parse(t: SceneTable, scene: SceneFile) -> tuple:
        t.allow({"map", "depth"})
        return (t.file("map", (".png",)) if "map" in t.table else None), t.bounded("depth", 0.0, 10.0, 0.1)

    (tmp_path / "snow.png").write_bytes(b"\x89PNG")
    (tmp_path.parent / "outside.png").write_bytes(b"\x89PNG")
    register_section(SceneSection("snow", parse))
    try:
        s = loads_scene('[snow]\nmap = "snow.png"\ndepth = 2\n', tmp_path / "s.toml")
        assert s.sections["snow"] == (tmp_path / "snow.png", 2.0)
        for bad, key, what in (('map = "../outside.png"', "snow.map", "leaves the scene's folder"), ('map = "snow.jpg"', "snow.map", "no such file"),
                               ('depth = 11', "snow.depth", "in [0, 10]"), ('depth = "x"', "snow.depth", "finite number")):
            with pytest.raises(SceneError) as info:
                loads_scene(f"[snow]\n{bad}\n", tmp_path / "s.toml")
            assert info.value.key == key and info.value.line == 2 and what in str(info.value), str(info.value)
    finally:
        unregister_section("snow")
