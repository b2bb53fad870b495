"""Light TOML input validation (issue 10 items 3, 6): non-finite and absurd values are refused at
the input (1e308 intensities baked infinities that `render` then refused), never a raw error."""

from __future__ import annotations

import os

import pytest

from piste.errors import FormatError
from piste.lighting.lights import load_lights, loads_lights


@pytest.mark.parametrize("body, field", [
    ('[[directional]]\ndirection = [0, 0, -1]\nintensity = 1e308\n', "directional[0].intensity"),
    ('[[directional]]\ndirection = [0, 0, -1]\nintensity = inf\n', "directional[0].intensity"),
    ('[[directional]]\ndirection = [0, 0, -1]\nintensity = nan\n', "directional[0].intensity"),
    ('[[directional]]\ndirection = [0, 0, -1]\nintensity = "bright"\n', "directional[0].intensity"),
    ('[[ambient]]\ncolor = "red"\n', "ambient[0].color"),
    ('[[ambient]]\ncolor = [1e300, 1, 1]\n', "ambient[0].color"),
    ('[[ambient]]\ncolor = ["a", "b", "c"]\n', "ambient[0].color"),
    ('[[point]]\nposition = [1e300, 0, 0]\n', "point[0].position"),
    ('[[point]]\nposition = [0, 0, 0]\nrange = -1\n', "point[0].range"),
    ('[[spot]]\nposition = [0, 0, 0]\ndirection = [0, 0, 0]\n', "spot[0].direction"),
    ('[[spot]]\nposition = [0, 0, 0]\ndirection = [0, 0, -1]\ninner_angle = 40\nouter_angle = 30\n', "spot[0]"),
    ('[[spot]]\nposition = [0, 0, 0]\ndirection = [0, 0, -1]\nfalloff = -1\n', "spot[0].falloff"),
])
def test_bad_value_is_a_format_error_naming_file_and_field(body, field):
    with pytest.raises(FormatError) as ei:
        loads_lights(body, "lights.toml")
    msg = str(ei.value)
    assert msg.startswith("lights.toml") and field in msg, msg


def test_sane_values_still_load():
    lights = loads_lights('[[directional]]\ndirection = [0, 0, -1]\nintensity = 1e5\n'
                          '[[ambient]]\ncolor = [0.2, 0.3, 0.4]\nintensity = -0.5\n', "ok.toml")
    assert len(lights.lights) == 2


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_fifo_refused(tmp_path):
    os.mkfifo(tmp_path / "l.toml")
    with pytest.raises(FormatError, match="not a regular file"):
        load_lights(tmp_path / "l.toml")
