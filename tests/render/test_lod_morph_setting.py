"""``--lod-morph on|off`` (demo, render, view) and the scene file's ``[lod] morph`` reach the
terrain renderer; the CLI wins over the scene file."""

from __future__ import annotations

import os

import pytest

from piste import cli
from piste.errors import ConfigError
from piste.terrain.resident import morph_setting
from piste.world.scene_file import loads_scene


@pytest.mark.parametrize("command", ["demo", "render", "view"])
def test_cli_flag_parses(command):
    extra = ["scene.toml"] if command == "render" else []
    args = cli.build_parser().parse_args([command, *extra, "--lod-morph", "off"])
    assert args.lod_morph == "off"
    assert cli.build_parser().parse_args([command, *extra]).lod_morph is None


def test_cli_override_wins_and_is_scoped(monkeypatch):
    monkeypatch.delenv("PISTE_LOD_MORPH", raising=False)
    assert morph_setting() is True and morph_setting(False) is False
    monkeypatch.setenv("PISTE_LOD_MORPH", "off")
    assert morph_setting(True) is False
    monkeypatch.setenv("PISTE_LOD_MORPH", "sideways")
    with pytest.raises(ConfigError, match="PISTE_LOD_MORPH"):
        morph_setting()
    monkeypatch.delenv("PISTE_LOD_MORPH")
    seen = {}

    def fake_run(args):
        seen["inside"] = morph_setting(True)
        return 0

    monkeypatch.setattr("piste.commands.render.run", fake_run)
    assert cli.main(["render", "x.toml", "--lod-morph", "off"]) == 0
    assert seen["inside"] is False
    assert "PISTE_LOD_MORPH" not in os.environ  # restored after the command


def test_scene_file_key(tmp_path):
    assert loads_scene('[lod]\nmorph = false\n', tmp_path / "s.toml").lod.morph is False
    assert loads_scene("", tmp_path / "s.toml").lod.morph is True
