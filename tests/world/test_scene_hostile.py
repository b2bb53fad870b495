"""Hostile scene and light TOML files (issue 10 item 3): deep nesting refused before tomllib
recurses, special files (pipes) refused before reading."""

from __future__ import annotations

import os

import pytest

from piste.errors import ConfigError
from piste.world.scene_file import loads_scene


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_terrain_source_fifo_refused(tmp_path):
    os.mkfifo(tmp_path / "h.png")
    with pytest.raises(ConfigError, match="not a regular file"):
        loads_scene('[terrain]\nsource = "h.png"\n', tmp_path / "scene.toml")


def test_deeply_nested_scene_and_lights_toml(tmp_path):
    from piste.errors import FormatError
    from piste.lighting import loads_lights

    deep = "x = " + "[" * 5000 + "]" * 5000 + "\n"
    with pytest.raises(ConfigError, match=r"s\.toml: arrays or tables nested more than 32 deep"):
        loads_scene(deep, tmp_path / "s.toml")
    with pytest.raises(FormatError, match=r"l\.toml: arrays or tables nested more than 32 deep"):
        loads_lights(deep, tmp_path / "l.toml")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_scene_file_fifo_refused(tmp_path):
    from piste.world.scene_file import load_scene

    os.mkfifo(tmp_path / "s.toml")
    with pytest.raises(ConfigError, match="not a regular file"):
        load_scene(tmp_path / "s.toml")


def test_path_too_long_for_the_file_system(tmp_path):
    text = '[[objects]]\nmodel = "' + "a" * 10000 + '"\nposition = [1.0, 2.0]\n'
    with pytest.raises(ConfigError, match=r"s\.toml, line 2, key 'objects\[0\]\.model': cannot use the path"):
        loads_scene(text, tmp_path / "s.toml")


def test_huge_toml_refused_before_parsing(tmp_path):
    from piste.errors import FormatError
    from piste.lighting import loads_lights

    text = 'name = "' + "a" * (17 << 20) + '"\n'
    with pytest.raises(ConfigError, match=r"s\.toml: .* more than the limit"):
        loads_scene(text, tmp_path / "s.toml")
    with pytest.raises(FormatError, match=r"l\.toml: .* more than the limit"):
        loads_lights(text, tmp_path / "l.toml")
