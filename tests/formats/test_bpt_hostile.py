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
