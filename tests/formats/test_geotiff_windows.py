"""Windowed GeoTIFF reads (issue 26 item 5): a window decodes only the tiles or strips under it,
has the bits of the whole read, allocates about the window, keeps the reader's defences; a tiled
build from a GeoTIFF fits the same tiles windowed as from the whole raster."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("tifffile")

from piste.errors import FormatError, PisteError  # noqa: E402
from piste.formats.geotiff import (open_geotiff_windows, read_geotiff, write_geotiff,  # noqa: E402
                                   write_geotiff_tiled)
from piste.pipeline.tiled_build import ArraySource, FileSource, SyntheticSource, TiledSpec, fit_task  # noqa: E402
from piste.terrain.tiles import TileGrid  # noqa: E402
from piste.world.scene_file import TerrainSpec  # noqa: E402

N = 2000


@pytest.fixture
def request_close():
    """Closes the windows a test opened when it ends."""
    opened = []

    def keep(win):
        opened.append(win)
        return win

    yield keep
    for win in opened:
        win.close()


@pytest.fixture(scope="module")
def field() -> np.ndarray:
    """(2000, 2000) float64 heights that float32 holds exactly (a fractal range, quantised)."""
    z = SyntheticSource((N, N), (10.0, 10.0), seed=3).window(slice(0, N), slice(0, N))
    return np.round(z * 8.0) / 8.0


@pytest.fixture(scope="module")
def files(field, tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("dem")
    out = {
        "tiled": write_geotiff(d / "tiled.tif", field, (10.0, 10.0), (500.0, 700.0), tile=(256, 256)),
        "striped": write_geotiff(d / "striped.tif", field, (10.0, 10.0), (500.0, 700.0), rowsperstrip=16),
        "zlib": write_geotiff(d / "zlib.tif", field, (10.0, 10.0), (500.0, 700.0), tile=(128, 256),
                              compression="zlib"),
        "generated": write_geotiff_tiled(d / "generated.tif", (N, N), lambda r, c: field[r, c], (10.0, 10.0),
                                         (500.0, 700.0), tile=(256, 128)),
        "uint16": write_geotiff_tiled(d / "uint16.tif", (N, N), lambda r, c: field[r, c], (10.0, 10.0),
                                      (500.0, 700.0), tile=(256, 256), dtype="uint16"),
    }
    return out


@pytest.mark.parametrize("kind", ["tiled", "striped", "zlib", "generated", "uint16"])
def test_windows_have_the_bits_of_the_whole_read(files, kind, request_close):
    whole = read_geotiff(files[kind])
    win = open_geotiff_windows(files[kind])
    request_close(win)
    assert win.shape == whole.z.shape == (N, N)
    assert win.spacing == whole.spacing and win.origin == whole.origin
    rng = np.random.default_rng(7)
    boxes = [(slice(0, N), slice(0, N)), (slice(N - 1, N), slice(0, 1)), (slice(255, 257), slice(255, 513))]
    for _ in range(6):
        r0, c0 = rng.integers(0, N - 1, 2)
        boxes.append((slice(int(r0), int(rng.integers(r0 + 1, N + 1))), slice(int(c0), int(rng.integers(c0 + 1, N + 1)))))
    for rows, cols in boxes:
        z, mask = win.read(rows, cols)
        assert z.dtype == np.float64 and not mask.any()
        assert np.array_equal(z, whole.z[rows, cols]), (rows, cols)


def test_a_window_allocates_about_the_window(files, request_close):
    whole_bytes = N * N * 8
    for kind in ("tiled", "striped", "zlib"):
        win = request_close(open_geotiff_windows(files[kind]))
        tracemalloc.start()
        try:
            z, _ = win.read(slice(900, 1100), slice(900, 1100))  # 200 x 200: 320 kB of float64
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert z.shape == (200, 200)
        assert peak < whole_bytes / 16, (kind, peak)  # the whole raster: 32 MB of float64
    # the whole-raster reader, for scale
    tracemalloc.start()
    try:
        read_geotiff(files["tiled"])
        peak_whole = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak_whole > whole_bytes


def _scene_terrain(path: Path, **kw) -> TerrainSpec:
    return TerrainSpec(kind="geotiff", path=path, samples_per_patch=3, tile_patches=64, **kw)


def test_tiled_build_fits_the_same_tiles_windowed_as_whole(files, field, tmp_path):
    src = FileSource(_scene_terrain(files["tiled"], height_scale=2.0, height_offset=-5.0))
    assert src.shape == (N, N) and src.spacing == (10.0, 10.0)
    grid = TileGrid(src.shape, 3, 64, src.spacing)
    whole = ArraySource(read_geotiff(files["tiled"]).z * 2.0 - 5.0, (10.0, 10.0), key="whole")
    windowed = TiledSpec(str(tmp_path / "win"), src, grid, res=2)
    reference = TiledSpec(str(tmp_path / "whole"), whole, grid, res=2)
    for t in [(0, 0), (3, 5), (grid.shape[0] - 1, grid.shape[1] - 1)]:
        rows, cols = grid.sample_window(*t)
        tracemalloc.start()
        try:
            z = src.window(rows, cols)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < N * N * 8 / 16  # one tile's samples, not the DEM
        assert np.array_equal(z, whole.window(rows, cols))
        fit_task(windowed, *t)
        fit_task(reference, *t)
        a, b = windowed.store.read("fit", *t), reference.store.read("fit", *t)
        assert np.array_equal(a["control_points"], b["control_points"]) and np.array_equal(a["uv"], b["uv"])


def test_missing_samples_windowed_and_whole(field, tmp_path, request_close):
    z = field[:300, :400].copy()
    z[10:14, 200:230] = -9999.0
    p = write_geotiff(tmp_path / "holes.tif", z, 5.0, nodata=-9999.0, tile=(64, 64))
    win = request_close(open_geotiff_windows(p))
    got, mask = win.read(slice(0, 64), slice(192, 256))
    assert mask.sum() == 4 * 30 and np.array_equal(got[~mask], z[:64, 192:256][~mask])
    assert np.array_equal(win.filled(slice(0, 64), slice(192, 256), 1.5)[mask], np.full(120, 1.5))
    with pytest.raises(FormatError, match=r"row 10, column 200.*GDAL_NODATA|GDAL_NODATA.*row 10, column 200"):
        win.filled(slice(0, 64), slice(192, 256), "error")
    # a tiled build with nearest fill takes the whole raster's fill (the nearest sample may be in another tile)
    src = FileSource(TerrainSpec(kind="geotiff", path=p, samples_per_patch=3, tile_patches=16))
    assert np.array_equal(src.window(slice(0, 49), slice(192, 241)), read_geotiff(p).z[0:49, 192:241])
    const = FileSource(TerrainSpec(kind="geotiff", path=p, samples_per_patch=3, tile_patches=16, nodata=0.0))
    assert np.array_equal(const.window(slice(0, 49), slice(192, 241)), read_geotiff(p, fill=0.0).z[0:49, 192:241])


def test_hostile_segment_tables_are_format_errors(field, tmp_path):
    import tifffile

    p = write_geotiff(tmp_path / "t.tif", field[:256, :256], 5.0, tile=(64, 64))
    data = bytearray(p.read_bytes())
    with tifffile.TiffFile(p) as tf:
        tag = tf.pages[0].tags["TileOffsets"]
        off, count = tag.valueoffset, tag.count
    # the last tile's offset past the end of the file
    bad = bytearray(data)
    bad[off + 4 * (count - 1): off + 4 * count] = (len(data) + 10).to_bytes(4, "little")
    q = tmp_path / "past_end.tif"
    q.write_bytes(bytes(bad))
    with pytest.raises(PisteError, match="past_end.tif"):
        open_geotiff_windows(q).read(slice(200, 256), slice(200, 256))
    # the file changes between opening and reading
    with open_geotiff_windows(p) as win:
        assert win.read(slice(0, 10), slice(0, 10))[0].shape == (10, 10)
        write_geotiff(p, field[:128, :256], 5.0, tile=(64, 64))
        with pytest.raises(FormatError, match="changed"):
            win.read(slice(0, 10), slice(0, 10))
    with pytest.raises(FormatError, match="closed"):
        win.read(slice(0, 10), slice(0, 10))


def test_mangled_tiled_files_are_read_or_refused_cleanly(field, tmp_path):
    seed = write_geotiff(tmp_path / "seed.tif", field[:200, :300], 5.0, tile=(64, 64), compression="zlib")
    data = seed.read_bytes()
    rng = np.random.default_rng(11)
    read = refused = 0
    for i in range(60):
        b = bytearray(data)
        for pos in rng.integers(0, len(b), int(rng.integers(1, 6))):
            b[int(pos)] = int(rng.integers(0, 256))
        q = tmp_path / f"m{i}.tif"
        q.write_bytes(bytes(b))
        try:
            with open_geotiff_windows(q) as win:
                h, w = win.shape
                win.read(slice(h // 3, h), slice(0, max(w // 2, 1)))
            read += 1
        except PisteError as exc:
            assert f"m{i}.tif" in str(exc)
            refused += 1
    assert read + refused == 60 and read > 0


def test_bad_window_slices_are_validation_errors(files, request_close):
    from piste.errors import ValidationError

    win = request_close(open_geotiff_windows(files["tiled"]))
    for rows, cols in [(slice(5, 5), slice(0, 3)), (slice(0, 10, 2), slice(0, 3)), (slice(N, N + 5), slice(0, 3))]:
        with pytest.raises(ValidationError, match="tiled.tif"):
            win.read(rows, cols)
