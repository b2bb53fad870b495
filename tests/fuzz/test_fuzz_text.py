"""Fuzz the text inputs: .bpt patch files (through PatchNet.from_bpt), scene TOML (load_scene) and
light TOML (load_lights), byte-wise and structurally (TOML values replaced by wrong types, huge and
negative numbers, hostile paths, deep nesting).  Each case loads or raises a PisteError naming the
file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import shutil
import tomllib

import numpy as np
import pytest
from fuzzlib import DATA, EXAMPLES, byte_mutations, check, doc_mutations, dump_toml, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.lighting import load_lights
from piste.terrain import PatchNet
from piste.world.scene_file import load_scene

REPO_DATA = EXAMPLES.parent / "src" / "piste" / "data"


# ---------------------------------------------------------------------------- .bpt
@pytest.fixture(scope="module")
def bpt_seed(tmp_path_factory):
    from piste.formats.bpt import write_bpt

    d = tmp_path_factory.mktemp("bpt")
    teapot = DATA / "patches" / "teapot.bpt"
    if teapot.exists():  # the first 4 patches of the teapot (small: fast cases)
        text = teapot.read_text().splitlines()
        body = [ln for ln in text[1:] if ln.strip()][: 4 * 17]
        (d / "seed.bpt").write_text("4\n" + "\n".join(body) + "\n")
    else:  # pragma: no cover
        g = np.zeros((4, 7, 3))
        g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(4.0))
        write_bpt(d / "seed.bpt", PatchNet.from_control_grid(g).control_points)
    return d / "seed.bpt"


def _load_bpt(path):
    net = PatchNet.from_bpt(path)
    assert np.isfinite(net.control_points).all()


def test_bpt_seed_loads(bpt_seed):
    assert check(_load_bpt, bpt_seed, "bpt seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(40)
def test_bpt_bytes(bpt_seed, data):
    target = bpt_seed.with_name("mutant.bpt")
    target.write_bytes(data.draw(byte_mutations(bpt_seed.read_bytes())))
    check(_load_bpt, target, "bpt byte-wise")


@given(data=st.data())
@fuzz_settings(30)
def test_bpt_lines(bpt_seed, data):
    """Whole-line edits: counts replaced by huge/negative/odd values, lines dropped or repeated."""
    lines = bpt_seed.read_text().splitlines()
    i = data.draw(st.integers(0, len(lines) - 1))
    new = data.draw(st.sampled_from(["2000000000", "-1", "0", "3 3", "4 4", "1e308 0 0", "nan 0 0", "0 0",
                                     "1 2 3 4", "", "x", "3", "99999999999999999999", lines[i] + " 1"]))
    action = data.draw(st.sampled_from(["replace", "insert", "delete"]))
    if action == "replace":
        lines[i] = new
    elif action == "insert":
        lines.insert(i, new)
    else:
        del lines[i]
    target = bpt_seed.with_name("mutant.bpt")
    target.write_text("\n".join(lines) + "\n")
    check(_load_bpt, target, "bpt line edits")


# ---------------------------------------------------------------------------- scene TOML
SCENES = sorted((EXAMPLES / "scenes").glob("*.toml"))


@pytest.fixture(params=SCENES, ids=[p.name for p in SCENES])
def scene_seed(request, tmp_path_factory):
    d = tmp_path_factory.mktemp("scene")
    shutil.copytree(EXAMPLES / "scenes" / "assets", d / "assets")
    shutil.copy(request.param, d / request.param.name)
    return d / request.param.name


def test_scene_seeds_load(scene_seed):
    assert check(load_scene, scene_seed, "scene seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(15)
def test_scene_bytes(scene_seed, data):
    target = scene_seed.with_name("mutant.toml")
    target.write_bytes(data.draw(byte_mutations(scene_seed.read_bytes())))
    check(load_scene, target, "scene byte-wise")


@given(data=st.data())
@fuzz_settings(40)
def test_scene_structure(scene_seed, data):
    doc = tomllib.loads(scene_seed.read_text())
    target = scene_seed.with_name("mutant.toml")
    target.write_bytes(dump_toml(data.draw(doc_mutations(doc))))
    check(load_scene, target, "scene structural")


# ---------------------------------------------------------------------------- light TOML
LIGHTS = [p for p in [REPO_DATA / "default_lights.toml"] if p.exists()]


@pytest.fixture(params=LIGHTS, ids=[p.name for p in LIGHTS])
def lights_seed(request, tmp_path_factory):
    d = tmp_path_factory.mktemp("lights")
    shutil.copy(request.param, d / request.param.name)
    return d / request.param.name


def test_lights_seeds_load(lights_seed):
    assert check(load_lights, lights_seed, "lights seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(30)
def test_lights_bytes(lights_seed, data):
    target = lights_seed.with_name("mutant.toml")
    target.write_bytes(data.draw(byte_mutations(lights_seed.read_bytes())))
    check(load_lights, target, "lights byte-wise")


@given(data=st.data())
@fuzz_settings(40)
def test_lights_structure(lights_seed, data):
    doc = tomllib.loads(lights_seed.read_text())
    target = lights_seed.with_name("mutant.toml")
    target.write_bytes(dump_toml(data.draw(doc_mutations(doc))))
    check(load_lights, target, "lights structural")
