"""SSX refusals name the file at fault (issue 24 item 4, issue 22): a bad page or tile in the
``.pbd`` is the ``.pbd``'s error (naming the ``_L.ssh`` it was checked against), a bad bank the
bank's, a bad project file the project's; the CLI prints one line without a traceback."""

from __future__ import annotations

import struct

import pytest

from piste.cli import main
from piste.errors import FormatError
from piste.pipeline.ssx_synth import make_level
from piste.formats.ssx.pbd import PATCH_SIZE
from piste.pipeline.ssx_level import load_level

PO = 0x90  # synthetic levels put the patches here


@pytest.fixture()
def lv(tmp_path):
    return make_level(rows=2, cols=2, seed=3).write(tmp_path, "LV")


def _poke(path, offset, fmt, value):
    data = bytearray(path.read_bytes())
    struct.pack_into(fmt, data, offset, value)
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("patch,value", [(0, 1), (2, -1), (3, 300)])
def test_bad_page_in_the_pbd_names_the_pbd(lv, patch, value):
    _poke(lv, PO + patch * PATCH_SIZE + 0x1B2, "<h", value)
    with pytest.raises(FormatError) as e:
        load_level(lv)
    msg = str(e.value)
    assert msg.startswith(str(lv)) and e.value.field == "lightmap_page"
    assert f"patch {patch}: light-map page {value} is not one of the 1 page(s) of LV_L.ssh" in msg


@pytest.mark.parametrize("word,value", [(0, 0.99), (1, -0.5), (0, 7.0)])
def test_bad_tile_rect_in_the_pbd_names_the_pbd(lv, word, value):
    _poke(lv, PO + PATCH_SIZE + 4 * word, "<f", value)
    with pytest.raises(FormatError, match="patch 1: light-map tile") as e:
        load_level(lv)
    assert str(e.value).startswith(str(lv)) and e.value.field == "lightmap_rect"


def test_bad_banks_name_the_bank(lv):
    lssh = lv.with_name("LV_L.ssh")
    good = lssh.read_bytes()
    lssh.write_bytes(good[:4] + b"\xff" * 12 + good[16:])
    with pytest.raises(FormatError) as e:
        load_level(lv)
    assert str(e.value).startswith(str(lssh))
    lssh.write_bytes(good)
    ssh = lv.with_name("LV.ssh")
    ssh.write_bytes(b"XXXX" + ssh.read_bytes()[4:])
    with pytest.raises(FormatError, match="magic") as e:
        load_level(lv)
    assert str(e.value).startswith(str(ssh))


def test_cli_names_the_pbd_in_one_line(lv, capsys):
    _poke(lv, PO + 0x1B2, "<h", 7)
    assert main(["ssx", "info", str(lv)]) != 0
    err = capsys.readouterr().err.strip()
    assert "LV.pbd" in err and "lightmap_page" in err and "LV_L.ssh" in err
    assert "Traceback" not in err and len(err.splitlines()) == 1
