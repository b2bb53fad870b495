"""GeoTIFF digital elevation models: heights with their georeferencing.

A GeoTIFF DEM is a one-band TIFF image of heights plus tags that place it on the ground:

* ``ModelPixelScaleTag`` (33550): ``(sx, sy, sz)``, the pixel size in the model's units;
* ``ModelTiepointTag`` (33922): ``(i, j, k, X, Y, Z)``, raster point ``(i, j)`` lies at ``(X, Y)``;
* ``GeoKeyDirectoryTag`` (34735): the model type (projected / geographic), the raster type
  (``PixelIsArea``: the tie point is a pixel's corner; ``PixelIsPoint``: its centre), the linear
  units of a projected system and the vertical units (metre, foot, US survey foot);
* ``GDAL_NODATA`` (42113): the value that marks missing samples (an ASCII number).

:func:`read_geotiff` returns a :class:`DemRaster` in piste's height-field layout (see
:mod:`piste.terrain.fit`): row ``r`` at ``y = origin[1] + r * dy`` with ``dy > 0`` (the file's
north-up rows are flipped so +y is north and x, y, z stay right-handed), heights in metres, pixel
centres as sample points.  A geographic raster (degrees) is converted to metres at its centre
latitude (``111,320 m * cos(lat)`` a degree of longitude, ``110,574 m`` a degree of latitude), good
to a fraction of a percent over a few kilometres.  Missing samples (nodata or non-finite) are filled
from the nearest valid sample (``fill="nearest"``), with a constant (``fill=<number>``), or refused
(``fill="error"``); ``mask`` says which samples were missing.

:func:`open_geotiff_windows` checks the same header and reads windows of a raster larger than
memory (:class:`GeoTiffWindows`): only the tiles or strips under a window are decoded, and a window
has exactly the bits of the same samples read whole (missing samples are reported, filled with a
number, or refused; ``"nearest"`` needs the whole raster).

:func:`write_geotiff` writes such a file (float32 heights, PixelIsArea, metres; strips or tiles,
optionally compressed), atomically; :func:`write_geotiff_tiled` writes a tiled one tile row by tile
row from a window function, for DEMs larger than memory.

Needs ``tifffile`` (the ``dask`` extra: ``pip install 'piste[dask]'``).
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, FormatError, PisteError, ValidationError
from piste.formats.atomic import atomic_path
from piste.formats.safe_io import open_file

__all__ = ["DemRaster", "GeoTiffWindows", "open_geotiff_windows", "read_geotiff", "write_geotiff",
           "write_geotiff_tiled", "MAX_SAMPLES", "UNIT_METRES"]

#: refuse rasters of more samples than this (a hostile header could claim anything)
MAX_SAMPLES = 1_500_000_000
#: a compressed raster may decode to at most this many times the file's size (LZW's 12-bit codes
#: reach ~2,730:1, deflate ~1,032:1); an uncompressed one to at most the file's size
MAX_EXPANSION = 4096
#: EPSG linear unit codes -> metres
UNIT_METRES = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0, 9036: 1000.0}
_UNIT_NAMES = {"metre": 9001, "meter": 9001, "m": 9001, "foot": 9002, "ft": 9002, "us_survey_foot": 9003,
               "us-ft": 9003}
_TAG_SCALE, _TAG_TIEPOINT, _TAG_TRANSFORM = 33550, 33922, 34264
_TAG_GEOKEYS, _TAG_DOUBLES, _TAG_NODATA = 34735, 34736, 42113
_KEY_MODEL, _KEY_RASTER, _KEY_LINEAR_UNITS, _KEY_VERTICAL_UNITS = 1024, 1025, 3076, 4099
_PIXEL_IS_AREA, _PIXEL_IS_POINT = 1, 2
_MODEL_PROJECTED, _MODEL_GEOGRAPHIC = 1, 2


def _tifffile() -> Any:
    try:
        import tifffile
    except ImportError:
        raise ConfigError("reading a GeoTIFF needs the 'dask' extra (tifffile): pip install 'piste[dask]'") from None
    return tifffile


@dataclass
class DemRaster:
    """A height field with its place on the ground.

    Attributes
    ----------
    z : (H, W) float64 metres, row ``r`` at ``y = origin[1] + r * spacing[1]`` (north up the rows)
    spacing : (dx, dy) metres between samples, both > 0
    origin : (x, y) metres of sample ``z[0, 0]`` in the file's projected system (for a geographic
        raster: metres east/north of longitude 0 at the centre latitude, an approximation)
    mask : (H, W) bool, True where the file had no data (filled in ``z``)
    vertical_units : the file's vertical unit name ("metre", "foot", "us_survey_foot")
    geographic : the file is in degrees (converted to metres)
    path : the file
    """

    z: np.ndarray
    spacing: tuple
    origin: tuple
    mask: np.ndarray
    vertical_units: str = "metre"
    geographic: bool = False
    path: Path | None = None

    @property
    def nodata_fraction(self) -> float:
        return float(self.mask.mean()) if self.mask.size else 0.0


_TAG_NAMES = {_TAG_SCALE: "ModelPixelScaleTag", _TAG_TIEPOINT: "ModelTiepointTag",
              _TAG_TRANSFORM: "ModelTransformationTag", _TAG_GEOKEYS: "GeoKeyDirectoryTag",
              _TAG_DOUBLES: "GeoDoubleParamsTag"}


def _numbers(path: Path, page: Any, code: int, dtype: npt.DTypeLike) -> np.ndarray:
    """A numeric tag's values, ``(n,)`` of ``dtype`` (FormatError naming the tag when it holds text,
    bytes, or integers past 64 bits)."""
    value = page.tags[code].value
    if isinstance(value, (str, bytes)):
        raise FormatError(path, f"{_TAG_NAMES[code]} must hold numbers, got text", field=_TAG_NAMES[code])
    try:
        return np.asarray(value, dtype=dtype).ravel()
    except (TypeError, ValueError, OverflowError) as exc:
        raise FormatError(path, f"{_TAG_NAMES[code]} must hold numbers ({exc})", field=_TAG_NAMES[code]) from None


def _geokeys(path: Path, page: Any) -> dict[int, Any]:
    """GeoKey id -> value (ints, doubles, or tuples of doubles) from the GeoKeyDirectory."""
    tags = page.tags
    if _TAG_GEOKEYS not in tags:
        return {}
    raw = _numbers(path, page, _TAG_GEOKEYS, np.int64)
    doubles = _numbers(path, page, _TAG_DOUBLES, np.float64) if _TAG_DOUBLES in tags else np.zeros(0)
    if len(raw) < 4 or len(raw) < 4 + 4 * int(raw[3]):
        raise FormatError(path, f"GeoKeyDirectory of {len(raw)} values is shorter than its header says",
                          field="GeoKeyDirectoryTag")
    keys: dict = {}
    for k in range(int(raw[3])):
        key, loc, count, off = (int(x) for x in raw[4 + 4 * k: 8 + 4 * k])
        if loc == 0:
            keys[key] = off
        elif loc == _TAG_DOUBLES and off + count <= len(doubles):
            keys[key] = tuple(float(x) for x in doubles[off:off + count])
    return keys


def _nodata(path: Path, page: Any) -> float | None:
    if _TAG_NODATA not in page.tags:
        return None
    text = page.tags[_TAG_NODATA].value
    text = text.decode("ascii", "replace") if isinstance(text, bytes) else str(text)
    text = text.strip().strip("\x00").strip()
    try:
        return float(text)
    except ValueError:
        raise FormatError(path, f"GDAL_NODATA must be a number, got {text!r}", field="GDAL_NODATA") from None


def _georeference(path: Path, page: Any, shape: tuple[int, ...]) -> tuple[tuple[float, float], tuple[float, float], bool, float]:
    """((sx, sy), (x0, y0) of pixel (0, 0)'s centre, geographic, z scale) in the file's units."""
    tags = page.tags
    keys = _geokeys(path, page)
    area = keys.get(_KEY_RASTER, _PIXEL_IS_AREA) != _PIXEL_IS_POINT
    if _TAG_SCALE in tags and _TAG_TIEPOINT in tags:
        scale = _numbers(path, page, _TAG_SCALE, np.float64)
        tie = _numbers(path, page, _TAG_TIEPOINT, np.float64)
        if len(scale) < 2 or len(tie) < 6:
            raise FormatError(path, f"expected 3 pixel scales and 6 tie-point values, got {len(scale)} and {len(tie)}",
                              field="ModelPixelScaleTag")
        sx, sy = float(scale[0]), float(scale[1])
        sz = float(scale[2]) if len(scale) > 2 and scale[2] != 0 else 1.0
        i, j, x, y = (float(v) for v in (tie[0], tie[1], tie[3], tie[4]))
        x0, y0 = x - i * sx, y + j * sy  # raster corner/centre (0, 0)
    elif _TAG_TRANSFORM in tags:
        m = _numbers(path, page, _TAG_TRANSFORM, np.float64)
        if len(m) != 16:
            raise FormatError(path, f"ModelTransformationTag must hold 16 values, got {len(m)}",
                              field="ModelTransformationTag")
        if m[1] != 0 or m[4] != 0:
            raise FormatError(path, "a rotated or sheared raster (ModelTransformationTag with off-diagonal terms) "
                                    "is not supported: resample it north-up first", field="ModelTransformationTag")
        sx, sy, sz, x0, y0 = float(m[0]), float(-m[5]), 1.0, float(m[3]), float(m[7])
    else:
        raise FormatError(path, "no georeferencing: expected ModelPixelScaleTag and ModelTiepointTag "
                                "(or ModelTransformationTag)", field="ModelPixelScaleTag")
    if not (np.isfinite([sx, sy, x0, y0]).all() and sx > 0 and sy != 0):
        raise FormatError(path, f"expected a positive finite pixel size, got ({sx}, {sy})", field="ModelPixelScaleTag")
    if area:  # the tie point is the pixel's corner: samples sit at pixel centres
        x0, y0 = x0 + 0.5 * sx, y0 - 0.5 * sy
    geographic = keys.get(_KEY_MODEL) == _MODEL_GEOGRAPHIC
    return (sx, sy), (x0, y0), geographic, sz


@dataclass(frozen=True)
class _Header:
    """What the checks of a GeoTIFF's first page found (everything but the samples)."""

    shape: tuple  # (H, W) samples, file rows north-up
    dtype: np.dtype
    scale: tuple  # (sx, sy) in the file's units (sy > 0: north-up rows)
    corner: tuple  # (x0, y0) of file pixel (0, 0)'s centre, file units
    geographic: bool
    keys: dict
    nodata: float | None
    vcode: int  # vertical unit (EPSG code)


def _open_tiff(path: Path) -> tuple[io.BufferedReader, Any]:
    """``(fh, TiffFile)`` of ``path``, opened through the confinement (:mod:`piste.formats.safe_io`)."""
    tifffile = _tifffile()
    if not path.is_file():
        raise FormatError(path, "no such file")
    fh = open_file(path, what="GeoTIFF")  # regular files only, race-free, no links (piste.formats.safe_io)
    try:
        tf = tifffile.TiffFile(fh)
    except Exception as exc:
        fh.close()
        raise FormatError(path, f"not a readable TIFF ({exc})") from None
    return fh, tf


def _header(path: Path, tf: Any, size: int, vertical_units: str | None) -> tuple[Any, _Header]:
    """(first page, :class:`_Header`): every check made before a sample is decoded."""
    if not tf.pages:
        raise FormatError(path, "not a readable TIFF (no image in the file)")
    page = tf.pages[0]
    try:
        shape = tuple(int(s) for s in page.shape)
        itemsize = np.dtype(page.dtype).itemsize
        compressed = int(page.compression) != 1
    except (TypeError, ValueError, OverflowError) as exc:
        raise FormatError(path, f"not a readable TIFF image header ({exc})", field="ImageWidth") from None
    need = int(np.prod(shape, dtype=object)) * itemsize
    if need > size * (MAX_EXPANSION if compressed else 1):
        raise FormatError(path, f"an image of shape {shape} needs {need:,} bytes of samples, more than a "
                                f"{'compressed ' if compressed else ''}file of {size:,} bytes can hold",
                          field="StripByteCounts")
    if len(shape) == 3 and 1 in (shape[0], shape[-1]):
        shape = tuple(s for s in shape if s != 1) if shape.count(1) < 2 else shape[:2]
    if len(shape) != 2:
        raise FormatError(path, f"expected one band of heights, got an image of shape {tuple(page.shape)}",
                          field="SamplesPerPixel")
    if shape[0] * shape[1] > MAX_SAMPLES or min(shape) < 2:
        raise FormatError(path, f"raster of {shape[0]} x {shape[1]} samples: expected 2 .. "
                                f"{MAX_SAMPLES:,} samples", field="ImageLength")
    (sx, sy), (x0, y0), geographic, _sz = _georeference(path, page, shape)
    keys = _geokeys(path, page)
    nodata = _nodata(path, page)
    if vertical_units is not None:
        if vertical_units not in _UNIT_NAMES:
            raise ConfigError(f"vertical_units must be one of {', '.join(sorted(_UNIT_NAMES))}, got {vertical_units!r}")
        vcode = _UNIT_NAMES[vertical_units]
    else:
        vcode = keys.get(_KEY_VERTICAL_UNITS, 9001)
        if vcode == 32767:  # user-defined: no information, take metres
            vcode = 9001
        if vcode not in UNIT_METRES:
            raise FormatError(path, f"vertical unit code {vcode} is not a known linear unit (metre 9001, foot 9002, "
                                    "US survey foot 9003): give vertical_units", field="VerticalUnitsGeoKey")
    return page, _Header(shape, np.dtype(page.dtype), (sx, sy), (x0, y0), geographic, keys, nodata, vcode)


def _place(hd: _Header) -> tuple[tuple, tuple]:
    """((dx, dy) metres, (x, y) metres of piste sample ``z[0, 0]``) of a header."""
    (sx, sy), (x0, y0), shape = hd.scale, hd.corner, hd.shape
    if hd.geographic:
        lat = np.radians(y0 - 0.5 * (shape[0] - 1) * sy)
        mx, my = 111_320.0 * np.cos(lat), 110_574.0
        sx, sy, x0, y0 = sx * mx, sy * my, x0 * mx, y0 * my
    else:
        f = UNIT_METRES.get(hd.keys.get(_KEY_LINEAR_UNITS, 9001), 1.0)
        sx, sy, x0, y0 = sx * f, sy * f, x0 * f, y0 * f
    if sy > 0:  # north-up rows (row 0 at the top, y decreasing) -> row r at y0' + r * dy
        y0 = y0 - (shape[0] - 1) * sy
    return (float(sx), float(abs(sy))), (float(x0), float(y0))


def _to_metres(hd: _Header, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """File samples (file rows) -> (heights in metres, missing mask), rows in piste order; the same
    element-wise steps for a whole raster and for a window, so a window has the whole raster's bits."""
    z = np.asarray(raw, dtype=np.float64)
    mask = ~np.isfinite(z)
    if hd.nodata is not None:
        mask |= z == hd.nodata
    z = z * UNIT_METRES[hd.vcode]
    if hd.scale[1] > 0:
        z, mask = z[::-1], mask[::-1]
    return np.ascontiguousarray(z), np.ascontiguousarray(mask)


def read_geotiff(path: str | os.PathLike[str], fill: float | str = "nearest", vertical_units: str | None = None) -> DemRaster:
    """Read a one-band GeoTIFF DEM (see the module docstring).

    Parameters
    ----------
    fill : ``"nearest"`` (default), a number (metres), or ``"error"`` (refuse missing samples)
    vertical_units : override the file's vertical unit ("metre", "foot", "us_survey_foot")

    Raises
    ------
    FormatError : not a TIFF, several bands, no georeferencing, a hostile size, missing samples
        with ``fill="error"``, an unknown vertical unit code.
    """
    path = Path(path)
    fh, tf = _open_tiff(path)
    with fh, tf:
        page, hd = _header(path, tf, path.stat().st_size, vertical_units)
        try:
            raw = np.asarray(page.asarray()).reshape(hd.shape)
        except Exception as exc:
            raise FormatError(path, f"could not decode the raster ({exc})") from None
    vname = {9001: "metre", 9002: "foot", 9003: "us_survey_foot", 9036: "kilometre"}[hd.vcode]
    z, mask = _to_metres(hd, raw)
    del raw
    if mask.all():
        raise FormatError(path, "every sample is nodata", field="GDAL_NODATA")
    spacing, origin = _place(hd)
    if mask.any():
        z = _fill(path, z, mask, fill)
    return DemRaster(z, spacing, origin, mask, vname, hd.geographic, path)


class GeoTiffWindows:
    """Windows of a GeoTIFF DEM read without reading the whole raster (:func:`open_geotiff_windows`).

    The file is opened once through the confinement (:mod:`piste.formats.safe_io`) and its header
    checked as :func:`read_geotiff` checks it, its segment table (offsets and byte counts, each
    within the file) read once; each :meth:`read` checks that the file at ``path`` is still the one
    opened (same inode, size and modification time: a FormatError otherwise) and decodes only the
    tiles or strips that meet the window: a window of ``h x w`` samples allocates about ``h x w``
    float64 plus one decoded tile (tiled files) or one strip (striped files; a file of one strip
    decodes it whole).  Windows carry the whole raster's bits: the same element-wise steps as
    :func:`read_geotiff` (unit factor, rows flipped to piste's south-up order).  Reads are
    serialised by a lock (threads of one process may share the object); :meth:`close` it when done
    (or use it as a context manager).

    Attributes
    ----------
    path, shape : (H, W) samples;  spacing : (dx, dy) metres;  origin : (x, y) of sample ``[0, 0]``
    vertical_units, geographic : as :class:`DemRaster`
    """

    def __init__(self, path: str | os.PathLike[str], vertical_units: str | None = None) -> None:
        import os
        import threading

        self.path = Path(path)
        fh, tf = _open_tiff(self.path)
        self._fh: io.BufferedReader | None = fh
        self._tf: Any = tf
        try:
            st = os.fstat(fh.fileno())
            self._stat = (st.st_ino, st.st_size, st.st_mtime_ns)
            self._page, self._hd = _header(self.path, self._tf, st.st_size, vertical_units)
            self._table = _segment_table(self.path, self._page, self._hd, st.st_size)
        except BaseException:
            self.close()
            raise
        self._lock = threading.Lock()
        self.shape = tuple(self._hd.shape)
        self.spacing, self.origin = _place(self._hd)
        self.vertical_units = {9001: "metre", 9002: "foot", 9003: "us_survey_foot", 9036: "kilometre"}[self._hd.vcode]
        self.geographic = self._hd.geographic

    def close(self) -> None:
        """Close the file (a later :meth:`read` raises a FormatError)."""
        tf, fh = getattr(self, "_tf", None), getattr(self, "_fh", None)
        self._tf = self._fh = None
        if tf is not None:
            tf.close()
        if fh is not None:
            fh.close()

    def __enter__(self) -> GeoTiffWindows:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def read(self, rows: slice, cols: slice) -> tuple[np.ndarray, np.ndarray]:
        """Samples ``z[rows, cols]`` in piste layout (row 0 the south edge), ``(h, w)`` float64 metres,
        and their missing mask ``(h, w)`` bool (nodata or non-finite, not filled: see
        :meth:`filled`).  ``rows``/``cols``: slices with step 1, clipped to the raster."""
        import os

        h, w = self.shape
        r0, r1, _ = rows.indices(h)
        c0, c1, _ = cols.indices(w)
        if rows.step not in (None, 1) or cols.step not in (None, 1) or r1 <= r0 or c1 <= c0:
            raise ValidationError(f"{self.path}: window rows {rows}, columns {cols} of a {h} x {w} raster: expected "
                                  "non-empty slices with step 1")
        fr0, fr1 = (h - r1, h - r0) if self._hd.scale[1] > 0 else (r0, r1)  # file rows (north-up)
        with self._lock:
            if self._tf is None:
                raise FormatError(self.path, "the GeoTIFF's windows were closed")
            try:
                st = os.stat(self.path)
                now = (st.st_ino, st.st_size, st.st_mtime_ns)
            except OSError:
                now = None
            if now != self._stat:
                raise FormatError(self.path, "the file changed while its windows were being read")
            raw = _read_window(self.path, self._tf, self._page, self._hd, self._table, fr0, fr1, c0, c1)
        return _to_metres(self._hd, raw)

    def filled(self, rows: slice, cols: slice, fill: float | str) -> np.ndarray:
        """:meth:`read` with missing samples set to ``fill`` (a number), or a FormatError naming the
        first one (``fill="error"``).  ``fill="nearest"`` needs the whole raster (the nearest
        valid sample may lie outside the window): use :func:`read_geotiff` for such a file."""
        z, mask = self.read(rows, cols)
        if not mask.any():
            return z
        if isinstance(fill, str) and fill == "nearest":
            raise ConfigError(f"{self.path}: a window holds missing samples and fill='nearest' needs the whole "
                              "raster: read it with read_geotiff or give fill a number")
        if isinstance(fill, str) and fill == "error":
            r, c = (int(v) for v in np.argwhere(mask)[0])
            r += rows.indices(self.shape[0])[0]
            c += cols.indices(self.shape[1])[0]
            raise FormatError(self.path, f"sample(s) have no data, first in this window at row {r}, column {c} "
                                         "(rows counted from the south edge): fill them or set fill",
                              field="GDAL_NODATA")
        return _fill(self.path, z, mask, fill)


def open_geotiff_windows(path: str | os.PathLike[str], vertical_units: str | None = None) -> GeoTiffWindows:
    """A :class:`GeoTiffWindows` of ``path``: the file opened, its header checked (the same
    FormatErrors as :func:`read_geotiff`) and its segment table read; no sample read yet."""
    return GeoTiffWindows(path, vertical_units)


def _segment_table(path: Path, page: Any, hd: _Header,
                   size: int) -> tuple[int, int, int, np.ndarray, np.ndarray] | None:
    """``(tile rows, tile columns, tiles across, offsets, bytecounts)`` of a one-band page whose
    segments can be addressed one by one, or None (decode the page whole)."""
    h, w = hd.shape
    try:
        if int(page.samplesperpixel) != 1 or int(getattr(page, "imagedepth", 1)) != 1:
            return None
        offsets = np.asarray(page.dataoffsets, dtype=np.int64)
        counts = np.asarray(page.databytecounts, dtype=np.int64)
        if page.is_tiled:
            th, tw = int(page.tilelength), int(page.tilewidth)
            what = "TileOffsets"
        else:
            th, tw = min(int(page.rowsperstrip), h), w
            what = "StripOffsets"
    except (TypeError, ValueError, OverflowError, AttributeError):
        return None
    if th < 1 or tw < 1:
        raise FormatError(path, f"expected positive tile or strip sizes, got {th} x {tw}", field=what)
    across = -(-w // tw)
    want = -(-h // th) * across
    if len(offsets) != want or len(counts) != want:
        raise FormatError(path, f"{len(offsets)} segment offsets and {len(counts)} byte counts for an image of "
                                f"{want} segments of {th} x {tw} samples", field=what)
    if (offsets < 0).any() or (counts < 0).any() or (offsets + counts > size).any():
        raise FormatError(path, f"a segment lies past the end of the file of {size:,} bytes", field=what)
    return th, tw, across, offsets, counts


def _read_window(path: Path, tf: Any, page: Any, hd: _Header,
                 table: tuple[int, int, int, np.ndarray, np.ndarray] | None, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """File rows ``r0:r1``, columns ``c0:c1`` of the page, ``(r1 - r0, c1 - c0)`` of its dtype,
    decoding only the segments that meet them (``table`` from :func:`_segment_table`; None: the
    segments cannot be addressed one by one, the whole page is decoded)."""
    try:
        if table is None:
            return np.asarray(page.asarray()).reshape(hd.shape)[r0:r1, c0:c1].copy()
        th, tw, across, offsets, counts = table
        out = np.zeros((r1 - r0, c1 - c0), dtype=hd.dtype)  # empty segments read as 0, as page.asarray does
        fh = tf.filehandle
        for ty in range(r0 // th, (r1 - 1) // th + 1):
            for tx in range(c0 // tw, (c1 - 1) // tw + 1):
                k = ty * across + tx
                if counts[k] == 0:
                    continue
                fh.seek(int(offsets[k]))
                data = fh.read(int(counts[k]))
                seg, _pos, _shape = page.decode(data, k, _fullsize=bool(page.is_tiled))
                if seg is None:
                    continue
                seg = np.asarray(seg).reshape(seg.shape[-3], seg.shape[-2])  # (rows, cols) of this segment
                y0, x0 = ty * th, tx * tw
                ya, yb = max(r0, y0), min(r1, y0 + seg.shape[0])
                xa, xb = max(c0, x0), min(c1, x0 + seg.shape[1])
                if yb > ya and xb > xa:
                    out[ya - r0:yb - r0, xa - c0:xb - c0] = seg[ya - y0:yb - y0, xa - x0:xb - x0]
        return out
    except PisteError:
        raise
    except Exception as exc:
        raise FormatError(path, f"could not decode the raster ({exc})") from None


def _fill(path: Path, z: np.ndarray, mask: np.ndarray, fill: float | str) -> np.ndarray:
    if isinstance(fill, str) and fill == "error":
        r, c = (int(v) for v in np.argwhere(mask)[0])
        raise FormatError(path, f"{int(mask.sum())} sample(s) have no data, first at row {r}, column {c} "
                                "(rows counted from the south edge): fill them or set fill", field="GDAL_NODATA")
    if isinstance(fill, str):
        if fill != "nearest":
            raise ConfigError(f"nodata fill must be 'nearest', 'error' or a number, got {fill!r}")
        from scipy.ndimage import distance_transform_edt

        idx = distance_transform_edt(mask, return_distances=False, return_indices=True)
        return z[idx[0], idx[1]]
    z = z.copy()
    z[mask] = float(fill)
    return z


def write_geotiff(path: str | os.PathLike[str], z: npt.ArrayLike, spacing: float | tuple[float, float], origin: npt.ArrayLike = (0.0, 0.0), nodata: float | None = None,
                  vertical_units: str = "metre", epsg: int | None = None, tile: tuple[int, int] | None = None,
                  rowsperstrip: int | None = None, compression: str | None = None) -> Path:
    """Write a north-up float32 GeoTIFF DEM (PixelIsArea), atomically.

    Parameters
    ----------
    z : (H, W) heights in piste layout (row ``r`` at ``y = origin[1] + r * dy``); written north-up
    spacing : float or (dx, dy) metres
    origin : (x, y) of sample ``z[0, 0]``'s centre (projected metres)
    nodata : GDAL_NODATA value (samples equal to it are missing)
    vertical_units : "metre", "foot" or "us_survey_foot" (heights are written as given, in that unit)
    epsg : ProjectedCSTypeGeoKey (optional; e.g. 32633)
    tile : (rows, cols) of each tile (multiples of 16) for a tiled file; default: strips
    rowsperstrip : rows of each strip (striped files); compression : e.g. ``"zlib"`` (default none)
    """
    tifffile = _tifffile()
    z = np.asarray(z, dtype=np.float32)
    h, w = z.shape
    extratags = _extratags(h, spacing, origin, nodata, vertical_units, epsg)
    layout = {"tile": tuple(tile)} if tile is not None else {"rowsperstrip": rowsperstrip} if rowsperstrip else {}
    path = Path(path)
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, np.ascontiguousarray(z[::-1]), extratags=extratags, photometric="minisblack",
                         compression=compression, **layout)
    return path


def write_geotiff_tiled(path: str | os.PathLike[str], shape: tuple[int, int], window_fn: Callable[[slice, slice], np.ndarray],
                        spacing: float | tuple[float, float], origin: npt.ArrayLike = (0.0, 0.0), tile: tuple[int, int] = (256, 256),
                        dtype: str = "float32", compression: str | None = None) -> Path:
    """Write a tiled north-up GeoTIFF DEM of ``shape = (H, W)`` samples tile by tile, atomically,
    never holding more than one row of tiles: for DEMs larger than memory (benchmarks, tests).

    ``window_fn(rows: slice, cols: slice)`` returns the heights of that window in piste layout
    (row ``r`` at ``y = origin[1] + r * dy``), ``(len(rows), len(cols))``; ``dtype`` ``"float32"``
    or ``"uint16"`` (heights rounded and clipped to 0 .. 65535).
    """
    tifffile = _tifffile()
    h, w = (int(v) for v in shape)
    th, tw = (int(v) for v in tile)
    dt = np.dtype(dtype)

    def tiles() -> Iterator[np.ndarray]:
        for fr in range(0, h, th):  # file rows, north-up: file row f is piste row h - 1 - f
            band = window_fn(slice(h - min(fr + th, h), h - fr), slice(0, w))[::-1]
            if dt.kind in "ui":
                band = np.clip(np.rint(band), np.iinfo(dt).min, np.iinfo(dt).max)
            band = band.astype(dt)
            for fc in range(0, w, tw):
                out = np.zeros((th, tw), dt)
                piece = band[:, fc:fc + tw]
                out[:piece.shape[0], :piece.shape[1]] = piece
                yield out

    extratags = _extratags(h, spacing, origin, None, "metre", None)
    path = Path(path)
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, tiles(), shape=(h, w), dtype=dt, tile=(th, tw), extratags=extratags,
                         photometric="minisblack", compression=compression, bigtiff=h * w * dt.itemsize > 2**31)
    return path


def _extratags(h: int, spacing: float | tuple[float, float], origin: npt.ArrayLike, nodata: float | None, vertical_units: str,
               epsg: int | None) -> list[tuple[int, str, int, Any, bool]]:
    """The GeoTIFF tags of a north-up PixelIsArea raster of ``h`` rows in metres."""
    sp = np.asarray(spacing, dtype=np.float64).reshape(-1)
    dx, dy = (float(sp[0]), float(sp[0])) if sp.size == 1 else (float(sp[0]), float(sp[1]))
    # corner of the north-west pixel
    o = np.asarray(origin, dtype=np.float64).reshape(-1)
    x_nw = float(o[0]) - 0.5 * dx
    y_nw = float(o[1]) + (h - 1) * dy + 0.5 * dy
    keys = [(_KEY_MODEL, 0, 1, _MODEL_PROJECTED), (_KEY_RASTER, 0, 1, _PIXEL_IS_AREA),
            (_KEY_LINEAR_UNITS, 0, 1, 9001), (_KEY_VERTICAL_UNITS, 0, 1, _UNIT_NAMES[vertical_units])]
    if epsg is not None:
        keys.insert(2, (3072, 0, 1, int(epsg)))
    keys.sort()
    geo = [1, 1, 0, len(keys)] + [v for k in keys for v in k]
    extratags: list[tuple[int, str, int, Any, bool]] = [
        (_TAG_SCALE, "d", 3, (dx, dy, 0.0), False),
        (_TAG_TIEPOINT, "d", 6, (0.0, 0.0, 0.0, x_nw, y_nw, 0.0), False),
        (_TAG_GEOKEYS, "H", len(geo), tuple(geo), False),
    ]
    if nodata is not None:
        extratags.append((_TAG_NODATA, "s", 0, f"{nodata:g}", False))
    return extratags
