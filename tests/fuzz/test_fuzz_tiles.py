"""Fuzz tiled worlds (piste.terrain.tiles.TileStore): a 2 x 2-tile world written by piste's own
TileStore in a session fixture, then its ``index.json`` mutated byte-wise and structurally (fields
of the wrong type, huge and negative counts, non-finite spacings, deep nesting) and its per-tile
``.npz`` files mutated byte-wise and member by member (wrong shapes, dtypes, non-finite values,
missing members).  Read as a viewer does: the index, the grid, every tile's net and the welded
neighbourhood of a tile.  Each case loads or raises a PisteError naming the mutated file, under a
time and a memory cap (see fuzzlib); a mutated index may be refused at the index or at a tile it
no longer matches, so its errors must name a file of the world."""

from __future__ import annotations

import io
import json
import shutil
import zipfile

import numpy as np
import pytest
from fuzzlib import COUNTS, byte_mutations, check, doc_mutations, dump_json, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.errors import FormatError
from piste.terrain.tiles import TILES_FORMAT, TileGrid, TileStore, fit_tile, neighbourhood_net, tile_net


@pytest.fixture(scope="session")
def tiled_world(tmp_path_factory):
    """A 2 x 2-tile world (25 x 25 samples, 3 samples a patch, 4 patches a tile side)."""
    root = tmp_path_factory.mktemp("tiles") / "world.tiles"
    y, x = np.mgrid[0:25, 0:25]
    z = 5.0 * np.sin(x / 4.0) + 0.3 * y
    g = TileGrid(z.shape, 3, 4, (2.0, 2.0), (100.0, 200.0))
    store = TileStore(root)
    store.write_index({"format": TILES_FORMAT, "grid": g.to_dict(), "tiles": {}})
    for ty, tx in g.tiles():
        r, c = g.sample_window(ty, tx)
        store.write("fit", ty, tx, fit_tile(g, ty, tx, z[r, c]), key=f"k{ty}{tx}")
    return root


def _copy(world, tmp_path_factory):
    d = tmp_path_factory.mktemp("w") / "world.tiles"
    shutil.copytree(world, d)
    return d


def _load(index_path):
    """What a viewer reads: index, grid, every tile's net (at most 16), tile (0, 0)'s neighbourhood."""
    store = TileStore(index_path.parent)
    store.read_index()
    grid = store.grid()
    for ty, tx in grid.tiles()[:16]:
        tile_net(store, ty, tx)
    neighbourhood_net(store, grid, 0, 0, ring=1)


def test_seed_loads(tiled_world):
    assert check(_load, tiled_world / "index.json", "tiles seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(20)
def test_index_bytes(tiled_world, tmp_path_factory, data):
    d = _copy(tiled_world, tmp_path_factory)
    (d / "index.json").write_bytes(data.draw(byte_mutations((tiled_world / "index.json").read_bytes())))
    check(_load, d / "index.json", "tiles index byte-wise", names="world.tiles")


@given(data=st.data())
@fuzz_settings(40)
def test_index_structure(tiled_world, tmp_path_factory, data):
    """index.json fields replaced by wrong types, huge/negative numbers, hostile paths, deleted."""
    d = _copy(tiled_world, tmp_path_factory)
    doc = json.loads((tiled_world / "index.json").read_text())
    (d / "index.json").write_bytes(dump_json(data.draw(doc_mutations(doc))))
    check(_load, d / "index.json", "tiles index structural", names="world.tiles")


@given(data=st.data())
@fuzz_settings(20)
def test_tile_bytes(tiled_world, tmp_path_factory, data):
    d = _copy(tiled_world, tmp_path_factory)
    name = data.draw(st.sampled_from(sorted(p.name for p in (d / "fit").iterdir())))
    tile = d / "fit" / name
    raw = tile.read_bytes()
    if data.draw(st.booleans()):  # stored, not deflated: mutations reach the .npy headers past the CRC
        with np.load(tile) as f:
            raw = _stored_npz({k: f[k] for k in f.files})
    tile.write_bytes(data.draw(byte_mutations(raw)))
    check(_load, d / "index.json", "tiles npz byte-wise", names=name)


def _stored_npz(arrays: dict) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k, v in arrays.items():
            b = io.BytesIO()
            np.lib.format.write_array(b, v, allow_pickle=False)
            zf.writestr(k + ".npy", b.getvalue())
    return buf.getvalue()


ARRAYS = st.sampled_from([
    np.zeros((0,)), np.zeros((16, 4, 4, 3)), np.zeros((15, 4, 4, 3)), np.zeros((16, 4, 4)), np.zeros((16, 4, 2)),
    np.full((16, 4, 4, 3), np.nan), np.full((16, 4, 4, 3), 1e308), np.zeros((16, 4, 4, 3), np.complex128),
    np.array(["a", "b"]), np.array(3.0), np.zeros((16, 4, 2), np.float32), np.full((16, 4, 2), np.inf, np.float32),
    np.zeros((100_000, 4, 4, 3)), np.zeros((16, 4, 4, 3), bool), np.zeros((4, 16, 4, 3)),
])


@given(data=st.data())
@fuzz_settings(30)
def test_tile_members(tiled_world, tmp_path_factory, data):
    """A tile's members replaced, removed or added (shapes, dtypes, non-finite values)."""
    d = _copy(tiled_world, tmp_path_factory)
    name = data.draw(st.sampled_from(sorted(p.name for p in (d / "fit").iterdir())))
    tile = d / "fit" / name
    with np.load(tile) as f:
        arrays = {k: f[k] for k in f.files}
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from(sorted(arrays) + ["control_points", "uv", "extra"]))
        if data.draw(st.booleans()) and key in arrays:
            del arrays[key]
        else:
            arrays[key] = data.draw(ARRAYS)
    tile.write_bytes(_stored_npz(arrays))
    check(_load, d / "index.json", "tiles npz members", names=name)


# ------------------------------------------------------------------------------ regressions (findings)
def _rewrite_tile(world, ty, tx, **arrays):
    store = TileStore(world)
    a = dict(store.read("fit", ty, tx))
    for k, v in arrays.items():
        if v is None:
            a.pop(k)
        else:
            a[k] = v
    store.write("fit", ty, tx, a, key="k")


@pytest.mark.parametrize("change,field", [
    ({"control_points": None}, "control_points"),  # was a raw KeyError
    ({"uv": np.zeros((15, 4, 2))}, "uv"),  # was ValueError: cannot reshape
    ({"control_points": np.array(["a", "b"])}, "control_points"),  # was ValueError: float('a')
    ({"control_points": np.full((16, 4, 4, 3), np.nan)}, "control_points"),  # was a ValidationError without the file
])
def test_bad_tile_members_name_the_tile_and_member(tiled_world, tmp_path_factory, change, field):
    d = _copy(tiled_world, tmp_path_factory)
    _rewrite_tile(d, 0, 1, **change)
    with pytest.raises(FormatError, match="t_0000_0001.npz") as e:
        tile_net(TileStore(d), 0, 1)
    assert e.value.field == field


def test_grid_that_no_longer_matches_the_tiles_is_a_format_error(tiled_world, tmp_path_factory):
    """Finding: tile_patches scaled in index.json gave a raw IndexError in neighbourhood_net."""
    d = _copy(tiled_world, tmp_path_factory)
    doc = json.loads((d / "index.json").read_text())
    doc["grid"]["tile_patches"] = 8
    (d / "index.json").write_text(json.dumps(doc))
    store = TileStore(d)
    with pytest.raises(FormatError, match="t_0000_0000.npz"):
        neighbourhood_net(store, store.grid(), 0, 0)


@pytest.mark.parametrize("key,value", [("samples", [1e308, 25]), ("samples", [25]), ("spacing", [float("nan"), 2.0]),
                                       ("samples_per_patch", True), ("origin", "here"), ("tile_patches", 2.5),
                                       ("samples", [10**9, 10**9])])
def test_hostile_grids_are_refused_naming_the_field(tiled_world, tmp_path_factory, key, value):
    """Findings: samples of 1e308 (OverflowError), NaN spacing accepted, 10^9 x 10^9 samples of 1-patch
    tiles (a grid of 10^16 tiles that grid.tiles() would try to list)."""
    d = _copy(tiled_world, tmp_path_factory)
    doc = json.loads((d / "index.json").read_text())
    doc["grid"][key] = value
    if key == "samples" and value[0] == 10**9:
        doc["grid"]["tile_patches"] = 1
    (d / "index.json").write_text(json.dumps(doc, allow_nan=True))
    with pytest.raises(FormatError, match="index.json") as e:
        TileStore(d).grid()
    assert e.value.field in (f"grid.{key}", "grid")


@pytest.mark.parametrize("content", ["[" * 100_000 + "]" * 100_000, None])
def test_index_nested_deeply_or_a_device_is_refused(tiled_world, tmp_path_factory, content):
    """Finding: a 100,000-deep index.json raised a raw RecursionError; a link to /dev/zero read forever."""
    d = _copy(tiled_world, tmp_path_factory)
    (d / "index.json").unlink()
    if content is None:
        (d / "index.json").symlink_to("/dev/zero")
    else:
        (d / "index.json").write_text(content)
    assert check(lambda p: TileStore(p.parent).grid(), d / "index.json", "tiles regressions") == "refused"


def test_tile_member_claiming_a_huge_shape_is_refused_before_allocating(tiled_world, tmp_path_factory):
    """Finding: a 200-byte tile whose uv.npy header says shape (10^11,) made numpy allocate 373 GiB
    (a MemoryError under the cap, inside the FormatError)."""
    d = _copy(tiled_world, tmp_path_factory)
    hdr = "{'descr': '<f4', 'fortran_order': False, 'shape': (100000000000,), }".ljust(117) + "\n"
    npy = b"\x93NUMPY\x01\x00" + len(hdr).to_bytes(2, "little") + hdr.encode() + b"\0" * 64
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("uv.npy", npy)
    (d / "fit" / "t_0000_0000.npz").write_bytes(buf.getvalue())
    assert check(lambda p: TileStore(d).read("fit", 0, 0), d / "fit" / "t_0000_0000.npz", "tiles regressions") == "refused"


# ------------------------------------------------------------------------------ streaming (piste render W.tiles)
# A built world (index.json with res, tiles and bounds; fit/ and lit/ tiles) read the way
# `piste render W.tiles` reads it, less the OpenGL: TileCache (index schema, far field of every
# tile), the flight's cameras, near tiles loaded by the loader thread, the draw list.  A bad tile is
# a TileError naming it, logged; the other tiles are still drawn.
@pytest.fixture(scope="session")
def built_world(tmp_path_factory):
    from piste.pipeline.tiled_build import build_tiles, synthetic_spec

    root = tmp_path_factory.mktemp("built") / "world.tiles"
    build_tiles(synthetic_spec(root, 8, tile_patches=4, res=3, spacing=20.0, shadows=False))
    return root


def _stream(index_path):
    """What `piste render W.tiles` does before OpenGL draws: TileCache, fly_path, near loads, draw list."""
    from piste.render.streaming import TileCache, fly_path

    cache = TileCache(index_path.parent, budget_bytes=64 << 20)
    try:
        cams = list(fly_path(cache.index, 3, speed=400.0))
        for cam in cams:
            cache.update(cam.eye)
            cache.wait_idle(timeout=5)
        cache.draw_list(cams[0].eye)
    finally:
        cache.close()
    if cache.bad:  # counted: a case whose bad tiles were left out while the rest was drawn
        c = COUNTS.setdefault("tiles stream: tile left out", {"cases": 0, "loaded": 0, "refused": 0})
        c["cases"] += 1
        c["refused"] += 1
        for e in cache.bad.values():
            assert "world.tiles" in str(e) and e.tile is not None, str(e)


def test_built_world_streams(built_world):
    assert check(_stream, built_world / "index.json", "tiles stream seeds") == "loaded"


@given(data=st.data())
@fuzz_settings(25)
def test_stream_index_structure(built_world, tmp_path_factory, data):
    """A built index.json's fields replaced (bounds, res, patches, tile keys, grid), removed, nested."""
    d = _copy(built_world, tmp_path_factory)
    doc = json.loads((built_world / "index.json").read_text())
    (d / "index.json").write_bytes(dump_json(data.draw(doc_mutations(doc))))
    check(_stream, d / "index.json", "tiles stream index structural", names="world.tiles")


@given(data=st.data())
@fuzz_settings(10)
def test_stream_index_bytes(built_world, tmp_path_factory, data):
    d = _copy(built_world, tmp_path_factory)
    (d / "index.json").write_bytes(data.draw(byte_mutations((built_world / "index.json").read_bytes())))
    check(_stream, d / "index.json", "tiles stream index byte-wise", names="world.tiles")


@given(data=st.data())
@fuzz_settings(15)
def test_stream_tile_bytes(built_world, tmp_path_factory, data):
    d = _copy(built_world, tmp_path_factory)
    product = data.draw(st.sampled_from(["fit", "lit"]))
    name = data.draw(st.sampled_from(sorted(p.name for p in (d / product).iterdir())))
    tile = d / product / name
    raw = tile.read_bytes()
    if data.draw(st.booleans()):  # stored: the mutations reach the .npy headers
        with np.load(tile) as f:
            raw = _stored_npz({k: f[k] for k in f.files})
    tile.write_bytes(data.draw(byte_mutations(raw)))
    check(_stream, d / "index.json", "tiles stream npz byte-wise", names="world.tiles")


LIT_ARRAYS = st.sampled_from([
    np.zeros((0,)), np.zeros((16, 3, 3, 3), np.uint8), np.zeros((16, 3, 3, 3), np.uint16), np.zeros((16, 4, 4, 3), np.uint8),
    np.zeros((5, 5, 3)), np.full((5, 5, 3), np.nan), np.full((5, 5, 3), 1e308), np.zeros((5, 5, 3), np.uint8),
    np.zeros((5, 5)), np.array(["a"]), np.zeros((10**6, 3), np.uint8), np.zeros((5, 5, 3), np.complex64),
    np.zeros((16, 4, 4, 3)), np.zeros((3,)),
])


@given(data=st.data())
@fuzz_settings(20)
def test_stream_tile_members(built_world, tmp_path_factory, data):
    """Members of a fit or lit tile replaced, removed or added (shapes, dtypes, non-finite values)."""
    d = _copy(built_world, tmp_path_factory)
    product = data.draw(st.sampled_from(["fit", "lit"]))
    name = data.draw(st.sampled_from(sorted(p.name for p in (d / product).iterdir())))
    tile = d / product / name
    with np.load(tile) as f:
        arrays = {k: f[k] for k in f.files}
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from(sorted(arrays) + ["texels", "far_positions", "far_colors", "control_points"]))
        if data.draw(st.booleans()) and key in arrays:
            del arrays[key]
        else:
            arrays[key] = data.draw(LIT_ARRAYS)
    tile.write_bytes(_stored_npz(arrays))
    check(_stream, d / "index.json", "tiles stream npz members", names="world.tiles")


@pytest.mark.parametrize("kind", ["link-out", "link-in", "folder-link", "fifo", "dev-zero", "folder", "missing"])
def test_hostile_tile_files_are_bad_tiles_and_the_rest_draws(built_world, tmp_path_factory, kind, caplog):
    """Findings (issue 24): symlinked tile files and folders were followed out of the world, a FIFO
    tile blocked the loader, a /dev/zero tile was 'pickled arrays'.  Now each is a TileError naming
    the tile, logged once, and the other tiles are still drawn; nothing blocks (time cap)."""
    import logging
    import os

    from piste.render.streaming import TileCache

    d = _copy(built_world, tmp_path_factory)
    outside = d.parent / "outside"
    shutil.copytree(d / "lit", outside)
    victim = d / "lit" / "t_0000_0001.npz"
    victim.unlink()
    if kind == "link-out":
        victim.symlink_to(outside / "t_0000_0001.npz")
    elif kind == "link-in":
        victim.symlink_to("t_0000_0000.npz")
    elif kind == "folder-link":
        shutil.rmtree(d / "lit")
        (d / "lit").symlink_to(outside, target_is_directory=True)
    elif kind == "fifo":
        os.mkfifo(victim)
    elif kind == "dev-zero":
        victim.symlink_to("/dev/zero")
    elif kind == "folder":
        victim.mkdir()

    def load(p):
        with caplog.at_level(logging.DEBUG, logger="piste"):
            cache = TileCache(p.parent, budget_bytes=64 << 20)
        cache.close()
        return cache

    assert check(load, d / "index.json", "tiles hostile files") == "loaded"
    caplog.clear()
    cache = load(d / "index.json")
    bad = {(0, 1)} if kind != "folder-link" else {(0, 0), (0, 1), (1, 0), (1, 1)}
    assert set(cache.bad) == bad and set(cache.tiles) == {(0, 0), (0, 1), (1, 0), (1, 1)} - bad
    e = cache.bad[(0, 1)]
    assert e.tile == (0, 1) and "t_0000_0001.npz" in str(e)
    want = {"link-out": "symbolic link", "link-in": "symbolic link", "folder-link": "symbolic link",
            "fifo": "a named pipe", "dev-zero": "symbolic link", "folder": "a folder", "missing": "no 'lit' output"}
    assert want[kind] in str(e), str(e)
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]  # warned once, however many
    assert len(warnings) == 1 and "tile (" in warnings[0].getMessage() and "the other tiles are" in \
        warnings[0].getMessage()
    assert len([r for r in caplog.records if "tile (" in r.getMessage()]) == len(bad)


@pytest.mark.parametrize("field,value,match", [
    (("tiles", "0,0", "bounds"), -0.0, r"tiles\.\"0,0\"\.bounds"),  # was a raw IndexError in piste render
    (("tiles", "0,0", "bounds"), [[0, 0, float("nan")], [1, 1, 1]], r"tiles\.\"0,0\"\.bounds"),
    (("tiles", "0,0", "bounds"), [[0, 0, 5], [1, 1, 1]], r"lo <= hi"),
    (("tiles", "0,0", "patches"), 10**12, r"tiles\.\"0,0\"\.patches"),
    (("tiles",), {}, "'tiles'"),
    (("tiles",), {"../../etc/passwd": {}}, "tile key"),
    (("tiles",), {"9,9": {}}, "no tile \\(9, 9\\)"),
    (("res",), 10**9, "'res'"),
    (("res",), None, "'res'"),
    (("extra",), 1, "unknown key 'extra'"),
])
def test_hostile_index_fields_name_the_field(built_world, tmp_path_factory, field, value, match):
    from piste.render.streaming import TileCache

    d = _copy(built_world, tmp_path_factory)
    doc = json.loads((d / "index.json").read_text())
    target = doc
    for k in field[:-1]:
        target = target[k]
    if value is None:
        del target[field[-1]]
    else:
        target[field[-1]] = value
    (d / "index.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=match) as e:
        TileCache(d, budget_bytes=64 << 20).close()
    assert "index.json" in str(e.value)


# ------------------------------------------------------------------------------ piste render W.tiles, end to end
def _mutate_world(d, data) -> None:
    """One mutation of a built world: its index (structural or byte-wise), a tile (byte-wise or
    member by member), or a tile file swapped for a link, a FIFO, /dev/zero or a folder."""
    import os

    how = data.draw(st.sampled_from(["index-doc", "index-bytes", "tile-bytes", "tile-members", "tile-file"]))
    if how.startswith("index"):
        raw = (d / "index.json").read_bytes()
        mutated = dump_json(data.draw(doc_mutations(json.loads(raw)))) if how == "index-doc" else \
            data.draw(byte_mutations(raw))
        (d / "index.json").write_bytes(mutated)
        return
    product = data.draw(st.sampled_from(["fit", "lit"]))
    tile = d / product / data.draw(st.sampled_from(sorted(p.name for p in (d / product).iterdir())))
    if how == "tile-bytes":
        tile.write_bytes(data.draw(byte_mutations(tile.read_bytes())))
    elif how == "tile-members":
        with np.load(tile) as f:
            arrays = {k: f[k] for k in f.files}
        key = data.draw(st.sampled_from(sorted(arrays)))
        if data.draw(st.booleans()):
            del arrays[key]
        else:
            arrays[key] = data.draw(LIT_ARRAYS)
        tile.write_bytes(_stored_npz(arrays))
    else:
        kind = data.draw(st.sampled_from(["link-out", "fifo", "dev-zero", "folder"]))
        tile.unlink()
        if kind == "link-out":
            tile.symlink_to(d.parent)
        elif kind == "fifo":
            os.mkfifo(tile)
        elif kind == "dev-zero":
            tile.symlink_to("/dev/zero")
        else:
            tile.mkdir()


def _render_cli(world, out) -> None:
    """``piste render WORLD.tiles``: exit 0, or exit 1 with one line naming a file of the world
    (raised here as a PisteError for the oracle); a raw exception escapes (a failure)."""
    import contextlib

    from piste.cli import main
    from piste.errors import PisteError

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["render", str(world), "--out", str(out), "--size", "64", "48", "--quiet"])
    lines = [ln for ln in err.getvalue().splitlines() if not ln.startswith("piste: ")]  # warnings: 'piste: ...'
    assert "Traceback" not in err.getvalue(), err.getvalue()
    if rc == 0:
        return
    assert rc == 1 and len(lines) == 1 and lines[0].startswith("piste render: error: "), (rc, err.getvalue())
    raise PisteError(lines[0])


@given(data=st.data())
@fuzz_settings(6)
def test_render_tiles_cli(built_world, tmp_path_factory, gl_context, data):
    """`piste render W.tiles` on a mutated world: a frame (bad tiles left out, warned) or one line
    naming a file of the world; never a raw traceback, a hang or a memory blow-up (the caps)."""
    d = _copy(built_world, tmp_path_factory)
    _mutate_world(d, data)
    check(lambda p: _render_cli(p.parent, p.parent.parent / "o.png"), d / "index.json", "tiles piste render",
          names="world.tiles")
