"""Fuzz height-field terrain sources (PNG and .npz): byte-wise mutants and .npz members replaced
by arrays of wrong shapes, types and values, loaded and fitted (load_terrain).  Each case loads or
raises a PisteError naming the file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import io
import shutil
import zipfile

import numpy as np
import pytest
from fuzzlib import EXAMPLES, byte_mutations, check, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.pipeline.sources import load_terrain
from piste.world.scene_file import TerrainSpec

ASSETS = EXAMPLES / "scenes" / "assets"
SEEDS = [p for p in [ASSETS / "hill.png", ASSETS / "valley.npz"] if p.exists()]


@pytest.fixture(params=SEEDS, ids=[p.name for p in SEEDS])
def seed(request, tmp_path_factory):
    d = tmp_path_factory.mktemp("hf")
    shutil.copy(request.param, d / request.param.name)
    return d / request.param.name


def _loader(path):
    spacing = (10.0, 10.0) if path.suffix == ".png" else None
    return lambda p: load_terrain(TerrainSpec(kind="heightfield", path=p, spacing=spacing))


def test_seeds_load(seed):
    assert check(_loader(seed), seed, "heightfield seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(15)
def test_heightfield_bytes(seed, data):
    target = seed.with_name("mutant" + seed.suffix)
    target.write_bytes(data.draw(byte_mutations(seed.read_bytes())))
    check(_loader(seed), target, "heightfield byte-wise")


ARRAYS = st.sampled_from([
    np.zeros((0,)), np.zeros((3, 3)), np.zeros((5, 5, 5)), np.full((9, 9), np.nan), np.full((9, 9), np.inf),
    np.full((9, 9), 1e308), np.array(-1.0), np.array(0.0), np.array([1.0, -2.0]), np.array(["a", "b"]),
    np.zeros((9, 9), dtype=np.complex128), np.zeros((9, 9), dtype=bool), np.arange(81, dtype=np.int8).reshape(9, 9),
    np.zeros((2, 100000)), np.array(np.nan),
])


@pytest.mark.skipif(not (ASSETS / "valley.npz").exists(), reason="no .npz seed")
@given(data=st.data())
@fuzz_settings(30)
def test_npz_members(tmp_path_factory, data):
    """.npz members replaced, removed or added: wrong shapes, dtypes, non-finite values."""
    with np.load(ASSETS / "valley.npz") as f:
        arrays = {k: f[k] for k in f.files}
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from(sorted(arrays) + ["spacing", "extra"]))
        if data.draw(st.booleans()) and key in arrays and len(arrays) > 1:
            del arrays[key]
        else:
            arrays[key] = data.draw(ARRAYS)
    d = tmp_path_factory.mktemp("npz")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k, v in arrays.items():
            b = io.BytesIO()
            np.lib.format.write_array(b, v, allow_pickle=False)
            zf.writestr(k + ".npy", b.getvalue())
    (d / "m.npz").write_bytes(buf.getvalue())
    check(lambda p: load_terrain(TerrainSpec(kind="heightfield", path=p)), d / "m.npz", "heightfield npz members")
