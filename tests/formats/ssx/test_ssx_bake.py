"""The game-format light-map bake: texel by texel against the GS formula, pages and rects."""

from __future__ import annotations

import numpy as np
import pytest

from piste.formats.ssx import extract_tiles, gs_blend, lightmap_pages, read_pbd, read_ssh
from piste.pipeline.ssx_synth import make_level
from piste.formats.ssx.lightmap import base_tiles, tile_params
from piste.lighting.lights import loads_lights
from piste.pipeline.ssx_level import bake_level, load_level, write_baked

LIGHTS = """
[[ambient]]
color = [0.5, 0.55, 0.7]
intensity = 0.3

[[directional]]
direction = [0.5, 0.3, -0.8]
color = [1.0, 0.9, 0.75]
intensity = 0.97
shadows = true
"""


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    d = tmp_path_factory.mktemp("bake")
    path = make_level(rows=3, cols=3, seed=5).write(d, "BK")
    level = load_level(path)
    level.pbd.lightmap_rect[:] = 0  # scrambled: the bake must place every tile again
    level.pbd.lightmap_page[:] = 3
    b = bake_level(level, loads_lights(LIGHTS), shadows=True)
    out = d / "OUT.pbd"
    write_baked(level, b, out)
    return level, b, out


def test_alpha_is_as_and_gs_blend_reproduces_the_light(baked):
    level, b, _ = baked
    tiles = extract_tiles(b.pages, b.lightmap_rect, b.lightmap_page)  # (n, 8, 8, 4)
    cs, as_ = tiles[..., :3], tiles[..., 3].astype(int)
    cl = b.cl.astype(int)
    # alpha = As = max(CL), 128 = 1.0 (over-bright up to 255)
    np.testing.assert_array_equal(as_, cl.max(axis=-1))
    assert as_.max() > 128  # the sun makes some texels over-bright
    # RGB = Cs against the patch's base texture reduced to 8x8: the GS blend gives back Cd x CL
    cd = base_tiles(level.reduced, level.pbd.texture_index, level.pbd.uv).astype(int)
    np.testing.assert_array_equal(cd, b.cd)
    got = gs_blend(cd, cs, as_).astype(int)
    want = np.minimum((cd * cl + 64) >> 7, 255)
    err = np.abs(got - want)
    lo = as_ <= 128
    assert lo.mean() > 0.2 and err[lo].max() <= 1  # faithful rounding where As <= 1.0
    assert err.max() <= 2 and err.mean() < 0.3
    # and Cs never exceeds Cd (a valid blend source)
    assert (cs.astype(int) <= cd).all()


def test_lighting_follows_the_surface(baked):
    level, b, _ = baked
    from piste.terrain.bezier import evaluate

    u, v = tile_params()
    _, nrm = evaluate(level.net.control_points, u, v)
    sun = -np.array([0.5, 0.3, -0.8]) / np.linalg.norm([0.5, 0.3, -0.8])
    ndl = (nrm @ sun).reshape(-1)
    lum = b.cl.reshape(-1, 3).astype(float).mean(axis=1)
    assert np.corrcoef(ndl, lum)[0, 1] > 0.8


def test_files_written_the_games_way(baked):
    level, b, out = baked
    p = read_pbd(out)
    assert (p.lightmap_page == 0).all()
    np.testing.assert_allclose(p.lightmap_rect[4], [4 / 16, 0, 1 / 16, 1 / 16])
    np.testing.assert_array_equal(p.control_points, level.pbd.control_points)  # geometry untouched
    pages = lightmap_pages(read_ssh(out.with_name("OUT_L.ssh")))
    np.testing.assert_array_equal(pages, b.pages)
    # the tile is stored transposed: page row = u, column = v
    k = 4
    x0 = 4 * 8
    np.testing.assert_array_equal(pages[0, 0 + 5, x0 + 2, 3], b.cl[k, 2, 5].max())
    # a level loaded from the written files renders the baked light
    lv = load_level(out)
    assert lv.info["lightmaps_file"] == "OUT_L.ssh"


def test_bake_is_the_same_in_worker_processes(baked):
    level, b, _ = baked
    again = bake_level(level, loads_lights(LIGHTS), shadows=True, jobs=2, chunk=4)
    np.testing.assert_array_equal(again.pages, b.pages)
    np.testing.assert_array_equal(again.lightmap_rect, b.lightmap_rect)


def test_bake_with_the_lights_of_a_scene_file(tmp_path):
    from piste.cli import main

    path = make_level(rows=1, cols=2, seed=1).write(tmp_path, "SC")
    (tmp_path / "lights.toml").write_text('[[lights]]\ntype = "ambient"\ncolor = [1.0, 0.2, 0.2]\nintensity = 0.9\n')
    assert main(["bake", str(path), "--format", "ssx-tricky", "--scene", str(tmp_path / "lights.toml"),
                 "--quiet", "--jobs", "1"]) == 0
    pages = lightmap_pages(read_ssh(tmp_path / "SC_L.ssh"))
    tiles = extract_tiles(pages, read_pbd(path).lightmap_rect, read_pbd(path).lightmap_page)
    # a red ambient light alone: As = the red channel of CL = round(0.9 * 128) everywhere
    assert (tiles[..., 3] == round(0.9 * 128)).all()


def test_bake_writes_only_the_source_and_the_bake_twice_the_same(tmp_path):
    """Issue 22: `piste ssx bake` twice gives identical bytes; the new level is the source with its
    light-map rects and pages updated (every other byte as read), its .ssh the source's bytes."""
    from piste.cli import main
    from piste.formats.ssx.pbd import PATCH_SIZE

    src = make_level(rows=2, cols=2, seed=3).write(tmp_path, "SRC")
    for k in ("a", "b"):
        (tmp_path / k).mkdir()
        assert main(["ssx", "bake", str(src), "--out", str(tmp_path / k / "NEW.pbd"), "--jobs", "1"]) == 0
    for f in ("NEW.pbd", "NEW.ssh", "NEW_L.ssh"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a" / "NEW.ssh").read_bytes() == (tmp_path / "SRC.ssh").read_bytes()
    old, new = read_pbd(src), read_pbd(tmp_path / "a" / "NEW.pbd")
    po, n = old.patch_offset, len(old)
    assert new.raw[:po] == old.raw[:po] and new.raw[po + n * PATCH_SIZE:] == old.raw[po + n * PATCH_SIZE:]
    keep = [f for f in old.records.dtype.names if f not in ("lightmap_rect", "lightmap_page")]
    for f in keep:
        np.testing.assert_array_equal(new.records[f], old.records[f])
