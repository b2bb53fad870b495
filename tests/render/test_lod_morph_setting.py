"""``--lod-morph on|off`` (demo, render, view) and the scene file's ``[lod] morph`` reach the
terrain renderer; the CLI wins over the scene file."""

from __future__ import annotations

import pytest

from piste import cli
from piste.terrain import resident as resident_module
from piste.terrain.resident import morph_setting
from piste.world.scene_file import loads_scene


@pytest.mark.parametrize("command", ["demo", "render", "view"])
def test_cli_flag_parses(command):
    extra = ["scene.toml"] if command == "render" else []
    args = cli.build_parser().parse_args([command, *extra, "--lod-morph", "off"])
    assert args.lod_morph == "off"
    assert cli.build_parser().parse_args([command, *extra]).lod_morph is None


def test_cli_flag_reaches_the_runtime_as_a_parameter(monkeypatch):
    """``--lod-morph`` is passed down (``lod_morph=``), not through the environment: the core reads
    no environment variable, and the command hands the runtime ``lod_morph=False``."""
    monkeypatch.setenv("PISTE_LOD_MORPH", "off")  # (once the channel; now ignored)
    assert morph_setting() is True and morph_setting(False) is False and morph_setting(True) is True
    seen = {}

    def fake_render_frames(bundle, camera=None, frames=1, **kw):
        seen["lod_morph"] = kw.get("lod_morph")
        return []

    monkeypatch.setattr("piste.pipeline.open_scene.open_source",
                        lambda *a, **k: type("B", (), {"visibility": None, "manifest": {}, "net": []})())
    monkeypatch.setattr("piste.pipeline.preview.render_frames", fake_render_frames)
    assert cli.main(["render", "x.toml", "--lod-morph", "off", "--out", "out/x.png"]) == 0
    assert seen["lod_morph"] is False
    assert cli.main(["render", "x.toml", "--out", "out/x.png"]) == 0
    assert seen["lod_morph"] is None  # the scene file's [lod] morph decides
    assert "PISTE_LOD_MORPH" not in open(resident_module.__file__, encoding="utf-8").read()


def test_scene_file_key(tmp_path):
    assert loads_scene('[lod]\nmorph = false\n', tmp_path / "s.toml").lod.morph is False
    assert loads_scene("", tmp_path / "s.toml").lod.morph is True
