"""Hostile .bpt files (issue 10 item 3): counts checked against the file's length before allocating."""

from __future__ import annotations

import os

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bpt import read_bpt, write_bpt


def test_huge_count_in_tiny_file_refused_before_allocating(tmp_path):
    p = tmp_path / "huge.bpt"
    p.write_text("2000000000000\n3 3\n" + "0 0 0\n" * 16)  # would be 358 GiB+ of float64
    with pytest.raises(FormatError, match=r"huge\.bpt, line 1: patch count 2000000000000 is more than"):
        read_bpt(p)


def test_count_just_beyond_the_file(tmp_path):
    p = tmp_path / "two.bpt"
    write_bpt(p, np.zeros((1, 4, 4, 3)))
    text = p.read_text().replace("1\n", "2\n", 1)
    p.write_text(text)
    with pytest.raises(FormatError, match=r"two\.bpt"):
        read_bpt(p)


def test_valid_roundtrip(tmp_path):
    cp = np.arange(2 * 48, dtype=np.float64).reshape(2, 4, 4, 3)
    write_bpt(tmp_path / "a.bpt", cp)
    np.testing.assert_array_equal(read_bpt(tmp_path / "a.bpt"), cp)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_fifo_refused(tmp_path):
    os.mkfifo(tmp_path / "p.bpt")
    with pytest.raises(FormatError, match="not a regular file"):
        read_bpt(tmp_path / "p.bpt")


def test_binary_refused(tmp_path):
    (tmp_path / "b.bpt").write_bytes(b"\xff\xfe\x00" * 10)
    with pytest.raises(FormatError, match="not a text file"):
        read_bpt(tmp_path / "b.bpt")


@pytest.mark.parametrize("point", ["1e300 0 0", "0 -1e300 0", "0 0 1.7976931348623157e308", "1e9 1e9 1e9"])
def test_absurd_coordinates_refused_naming_the_line(tmp_path, point):
    """Issue 24: coordinates near 1e300 once reached scipy's k-d tree (through an infinite welding
    tolerance) as a raw ValueError; they are refused by the reader, naming the file, line and point."""
    p = tmp_path / "far.bpt"
    write_bpt(p, np.zeros((1, 4, 4, 3)))
    lines = p.read_text().splitlines()
    lines[7] = point  # control point 5 of patch 0
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError, match=r"far\.bpt, line 8: expected control point 5 of patch 0 .* within \+-1e\+08"):
        read_bpt(p)


def test_large_but_plausible_coordinates_load(tmp_path):
    """UTM-sized metres (a northing of 9,999,000 m) are kept."""
    cp = np.zeros((1, 4, 4, 3))
    cp[..., 0] = 500_000.0
    cp[..., 1] = 9_999_000.0 + np.arange(4)[:, None]
    write_bpt(tmp_path / "utm.bpt", cp)
    np.testing.assert_array_equal(read_bpt(tmp_path / "utm.bpt"), cp)
