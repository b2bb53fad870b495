"""Fuzz the SSX Tricky formats (synthetic files from piste.formats.ssx.synth, no retail data):
.pbd levels (read and turned into a patch net), .ssh texture and light-map banks (one with kept
hot-spot and metal-alpha chunks, read and written back), whole levels (one of the three files
mutated, the level loaded: the refusal must name the mutated file first), and .mpf models (piste's
encoder's output, read and decoded).  Byte-wise mutants; each case loads or raises a PisteError
naming the file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import shutil
import struct

import pytest
from fuzzlib import byte_mutations, check, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

ssx = pytest.importorskip("piste.formats.ssx")

from piste.pipeline.ssx_level import pbd_to_net  # noqa: E402
from piste.pipeline.ssx_synth import make_level  # noqa: E402


@pytest.fixture(scope="module")
def level(tmp_path_factory):
    d = tmp_path_factory.mktemp("ssx")
    pbd = make_level(rows=2, cols=2, n_textures=2).write(d, "SYNTH")
    return {"pbd": pbd, "ssh": d / "SYNTH.ssh", "lightmap": d / "SYNTH_L.ssh"}


@pytest.fixture(scope="module")
def mpf_file(tmp_path_factory):
    from piste.character.rider import default_rider

    d = tmp_path_factory.mktemp("mpf")
    mpf, _ = ssx.model_to_mpf(default_rider(0))
    ssx.write_mpf(mpf, d / "RIDER.mpf")
    return d / "RIDER.mpf"


def _pbd(path):
    pbd_to_net(ssx.read_pbd(path))


def _mpf(path):
    ssx.mpf_to_model(ssx.read_mpf(path))


def _ssh_round_trip(path):
    bank = ssx.read_ssh(path)
    ssx.parse_ssh(bank.to_bytes(), path)


LOADERS = {"pbd": _pbd, "ssh": ssx.read_ssh, "lightmap": ssx.read_ssh, "kept": _ssh_round_trip}


@pytest.fixture(scope="module")
def kept(tmp_path_factory, level):
    """The level's texture bank with a hot-spot list (124) and a metal-alpha marker (105) added."""
    bank = ssx.read_ssh(level["ssh"])
    body = struct.pack("<h", 2) + struct.pack("<4i", 10, 20, 30, 40)
    n = 4 + len(body) + (-(4 + len(body)) % 16)
    bank.images[0].extra = [(2, (struct.pack("<I", 124 | (n << 8)) + body).ljust(n, b"\0"))]
    bank.images[1].extra = [(2, struct.pack("<I4hI", 105 | (16 << 8), 0, 128, 0, 0, 0))]
    path = tmp_path_factory.mktemp("kept") / "KEPT.ssh"
    path.write_bytes(bank.to_bytes())
    return path


@pytest.fixture(scope="module")
def files(level, kept):
    return {**level, "kept": kept}


@pytest.mark.parametrize("kind", sorted(LOADERS))
def test_seeds_load(files, kind):
    assert check(LOADERS[kind], files[kind], "ssx seeds") == "loaded"


@pytest.mark.parametrize("kind", sorted(LOADERS))
@given(data=st.data())
@fuzz_settings(20)
def test_ssx_level_bytes(files, kind, tmp_path_factory, data):
    seed = files[kind]
    target = tmp_path_factory.mktemp("m") / ("MUTANT" + seed.suffix)
    target.write_bytes(data.draw(byte_mutations(seed.read_bytes())))
    check(LOADERS[kind], target, f"ssx {kind} byte-wise")


def _level_naming_the_mutant(mutant):
    """Load the level the mutated file belongs to; a refusal must begin with the mutated file's
    path (the file at fault), not another file of the level."""
    from piste.errors import PisteError
    from piste.pipeline.ssx_level import load_level

    try:
        load_level(mutant.parent / "SYNTH.pbd")
    except PisteError as exc:
        if not str(exc).startswith(str(mutant)):
            raise AssertionError(f"mutating {mutant.name} was blamed on another file: {exc}") from None
        raise


@pytest.mark.parametrize("kind", ["pbd", "ssh", "lightmap"])
@given(data=st.data())
@fuzz_settings(20)
def test_whole_level_names_the_mutated_file(level, kind, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("lv")
    for f in level.values():
        shutil.copy(f, d / f.name)
    target = d / level[kind].name
    target.write_bytes(data.draw(byte_mutations(level[kind].read_bytes())))
    check(_level_naming_the_mutant, target, f"ssx level, {kind} mutated")


def test_mpf_seed_loads(mpf_file):
    assert check(_mpf, mpf_file, "ssx seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(20)
def test_mpf_bytes(mpf_file, tmp_path_factory, data):
    target = tmp_path_factory.mktemp("m") / "MUTANT.mpf"
    target.write_bytes(data.draw(byte_mutations(mpf_file.read_bytes())))
    check(_mpf, target, "ssx mpf byte-wise")
