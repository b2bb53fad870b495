"""GeoTIFF DEMs: georeferencing (pixel size, origin, pixel-is-area), nodata, vertical units, errors,
and a GeoTIFF terrain in a scene file fitted by ``piste build``."""

from __future__ import annotations

import numpy as np
import pytest

tifffile = pytest.importorskip("tifffile")

from piste.errors import ConfigError, FormatError  # noqa: E402
from piste.formats.geotiff import read_geotiff, write_geotiff  # noqa: E402


def _hill(h=25, w=33, dx=10.0, dy=12.5):
    y, x = np.mgrid[0:h, 0:w]
    return 300.0 + 40.0 * np.sin(x * dx / 90.0) * np.cos(y * dy / 110.0) + 0.3 * x * dx


def test_round_trip_georeferencing(tmp_path):
    z = _hill()
    write_geotiff(tmp_path / "d.tif", z, (10.0, 12.5), origin=(512_000.0, 4_100_000.0), epsg=32633)
    dem = read_geotiff(tmp_path / "d.tif")
    assert dem.spacing == (10.0, 12.5)
    assert dem.origin == (512_000.0, 4_100_000.0)  # the centre of the south-west pixel
    assert np.allclose(dem.z, z.astype(np.float32))  # rows back in piste order (row 0 = south)
    assert not dem.mask.any() and dem.vertical_units == "metre" and not dem.geographic
    # tifffile's own GeoTIFF decoder sees the same tie point (north-west pixel corner)
    with tifffile.TiffFile(tmp_path / "d.tif") as tf:
        g = tf.pages[0].geotiff_tags
    assert g["ModelTiepoint"][3:5] == [512_000.0 - 5.0, 4_100_000.0 + 24 * 12.5 + 6.25]


def test_nodata_fill_modes_and_mask(tmp_path):
    z = _hill(9, 11)
    z[3, 4] = z[3, 5] = -9999.0
    write_geotiff(tmp_path / "n.tif", z, 5.0, nodata=-9999.0)
    dem = read_geotiff(tmp_path / "n.tif")
    assert dem.mask.sum() == 2 and dem.mask[3, 4] and dem.mask[3, 5]
    z32 = z.astype(np.float32)
    assert dem.z[3, 4] in (z32[3, 3], z32[2, 4], z32[4, 4])  # a nearest valid sample (distance 1)
    assert dem.z[3, 5] in (z32[3, 6], z32[2, 5], z32[4, 5])
    assert (dem.z > 0).all()
    assert read_geotiff(tmp_path / "n.tif", fill=100.0).z[3, 4] == 100.0
    with pytest.raises(FormatError, match="2 sample.*row 3, column 4"):
        read_geotiff(tmp_path / "n.tif", fill="error")
    with pytest.raises(ConfigError, match="nodata fill"):
        read_geotiff(tmp_path / "n.tif", fill="bogus")


def test_vertical_units_feet(tmp_path):
    z = _hill(5, 6)
    write_geotiff(tmp_path / "ft.tif", z, 3.0, vertical_units="foot")
    dem = read_geotiff(tmp_path / "ft.tif")
    assert dem.vertical_units == "foot"
    assert np.allclose(dem.z, z.astype(np.float32) * 0.3048)
    assert np.allclose(read_geotiff(tmp_path / "ft.tif", vertical_units="metre").z, z.astype(np.float32))


def test_geographic_raster_in_metres(tmp_path):
    z = np.arange(20, dtype=np.float32).reshape(4, 5)
    geo = (1, 1, 0, 2, 1024, 0, 1, 2, 1025, 0, 1, 2)  # geographic, PixelIsPoint
    tifffile.imwrite(tmp_path / "g.tif", z, extratags=[
        (33550, "d", 3, (1 / 3600, 1 / 3600, 0.0), False),
        (33922, "d", 6, (0.0, 0.0, 0.0, 10.0, 60.0, 0.0), False),
        (34735, "H", len(geo), geo, False)])
    dem = read_geotiff(tmp_path / "g.tif")
    assert dem.geographic
    lat = np.radians(60.0 - 1.5 / 3600)
    assert np.isclose(dem.spacing[0], 111_320.0 * np.cos(lat) / 3600)  # ~15.5 m at 60 degrees north
    assert np.isclose(dem.spacing[1], 110_574.0 / 3600)
    assert np.array_equal(dem.z[0], z[-1])  # south row first


def test_bad_files(tmp_path):
    tifffile.imwrite(tmp_path / "plain.tif", np.zeros((4, 4), np.float32))
    with pytest.raises(FormatError, match="no georeferencing"):
        read_geotiff(tmp_path / "plain.tif")
    (tmp_path / "junk.tif").write_bytes(b"II*\x00garbage")
    with pytest.raises(FormatError, match="not a readable TIFF"):
        read_geotiff(tmp_path / "junk.tif")
    tifffile.imwrite(tmp_path / "rgb.tif", np.zeros((4, 4, 3), np.uint8), photometric="rgb",
                     extratags=[(33550, "d", 3, (1.0, 1.0, 0.0), False), (33922, "d", 6, (0,) * 6, False)])
    with pytest.raises(FormatError, match="one band"):
        read_geotiff(tmp_path / "rgb.tif")
    z = np.full((4, 4), -1.0)
    write_geotiff(tmp_path / "empty.tif", z, 1.0, nodata=-1.0)
    with pytest.raises(FormatError, match="every sample is nodata"):
        read_geotiff(tmp_path / "empty.tif")
    with pytest.raises(FormatError, match="no such file"):
        read_geotiff(tmp_path / "missing.tif")


def test_geotiff_scene_fits_through_piste_build(tmp_path, capsys):
    from piste.cli import main
    try:  # the bundle reader moves to the pipeline layer (in flight while this was written)
        from piste.pipeline.bundle_objects import load_bundle
    except ImportError:  # pragma: no cover
        from piste.formats.bundle import load_bundle
    from piste.terrain.fit import fit_error

    z = _hill(25, 33, 10.0, 12.5)
    z[10, 10] = -32768.0
    write_geotiff(tmp_path / "dem.tif", z, (10.0, 12.5), origin=(700_000.0, 5_000_000.0), nodata=-32768.0)
    (tmp_path / "s.toml").write_text('[terrain]\nsource = "dem.tif"\nnodata = "nearest"\n'
                                     "[lightmap]\nres = 4\n[visibility]\ncell = 100.0\n")
    assert main(["build", str(tmp_path / "s.toml"), "--quiet", "--no-cache"]) == 0
    b = load_bundle(tmp_path / "s.piste")
    assert b.manifest["terrain"]["kind"] == "geotiff"
    lo, hi = b.net.bounds
    # spacing from the file's tags: 8 x 6 patches of 4 sample intervals, placed at the origin
    assert np.allclose(lo[:2], 0.0) and np.allclose(hi[:2], (320.0, 300.0))
    dem = read_geotiff(tmp_path / "dem.tif")
    rmse, mx, count = fit_error(b.net, dem.z, dem.spacing)
    assert count == 25 * 33 and rmse < 1.0 and mx < 6.0
    # a wrong nodata keyword is a scene error naming the key
    (tmp_path / "bad.toml").write_text('[terrain]\nsource = "dem.tif"\nnodata = "zero"\n')
    assert main(["build", str(tmp_path / "bad.toml"), "--quiet"]) == 1
    assert "terrain.nodata" in capsys.readouterr().err
