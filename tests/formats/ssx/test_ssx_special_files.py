"""SSX readers refuse what is not a regular file (a pipe would hang a plain read, /dev/zero would fill
memory) and files over their size limit, with a FormatError naming the file."""

from __future__ import annotations

import os

import pytest

from piste.errors import FormatError
from piste.formats.ssx import mpf, pbd, ssh

READERS = [pbd.read_pbd, ssh.read_ssh, mpf.read_mpf]


@pytest.mark.parametrize("reader", READERS, ids=lambda r: r.__name__)
def test_pipe_device_folder_and_missing_file_are_refused(reader, tmp_path):
    fifo = tmp_path / "level.pbd"
    os.mkfifo(fifo)
    for bad in (fifo, "/dev/zero", tmp_path, tmp_path / "missing.pbd"):
        with pytest.raises(FormatError) as e:
            reader(bad)
        assert str(bad) in str(e.value)


@pytest.mark.parametrize("module", [pbd, ssh, mpf], ids=lambda m: m.__name__)
def test_oversized_file_is_refused_before_reading(module, tmp_path, monkeypatch):
    path = tmp_path / "big.bin"
    path.write_bytes(b"\0" * 4096)
    monkeypatch.setattr(module, "MAX_FILE_BYTES", 1024)
    reader = {pbd: pbd.read_pbd, ssh: ssh.read_ssh, mpf: mpf.read_mpf}[module]
    with pytest.raises(FormatError, match="limit"):
        reader(path)
