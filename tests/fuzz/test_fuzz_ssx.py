"""Fuzz the SSX Tricky formats (synthetic files from piste.formats.ssx.synth, no retail data):
.pbd levels (read and turned into a patch net), .ssh texture and light-map banks, and .mpf models
(piste's encoder's output, read and decoded).  Byte-wise mutants; each case loads or raises a
PisteError naming the file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import pytest
from fuzzlib import byte_mutations, check, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

ssx = pytest.importorskip("piste.formats.ssx")


@pytest.fixture(scope="module")
def level(tmp_path_factory):
    d = tmp_path_factory.mktemp("ssx")
    pbd = ssx.make_level(rows=2, cols=2, n_textures=2).write(d, "SYNTH")
    return {"pbd": pbd, "ssh": d / "SYNTH.ssh", "lightmap": d / "SYNTH_L.ssh"}


@pytest.fixture(scope="module")
def mpf_file(tmp_path_factory):
    from piste.character.rider import default_rider

    d = tmp_path_factory.mktemp("mpf")
    mpf, _ = ssx.model_to_mpf(default_rider(0))
    ssx.write_mpf(mpf, d / "RIDER.mpf")
    return d / "RIDER.mpf"


def _pbd(path):
    ssx.read_pbd(path).to_net()


def _mpf(path):
    ssx.mpf_to_model(ssx.read_mpf(path))


LOADERS = {"pbd": _pbd, "ssh": ssx.read_ssh, "lightmap": ssx.read_ssh}


@pytest.mark.parametrize("kind", sorted(LOADERS))
def test_seeds_load(level, kind):
    assert check(LOADERS[kind], level[kind], "ssx seeds") == "loaded"


@pytest.mark.parametrize("kind", sorted(LOADERS))
@given(data=st.data())
@fuzz_settings(20)
def test_ssx_level_bytes(level, kind, tmp_path_factory, data):
    seed = level[kind]
    target = tmp_path_factory.mktemp("m") / ("MUTANT" + seed.suffix)
    target.write_bytes(data.draw(byte_mutations(seed.read_bytes())))
    check(LOADERS[kind], target, f"ssx {kind} byte-wise")


def test_mpf_seed_loads(mpf_file):
    assert check(_mpf, mpf_file, "ssx seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(20)
def test_mpf_bytes(mpf_file, tmp_path_factory, data):
    target = tmp_path_factory.mktemp("m") / "MUTANT.mpf"
    target.write_bytes(data.draw(byte_mutations(mpf_file.read_bytes())))
    check(_mpf, target, "ssx mpf byte-wise")
