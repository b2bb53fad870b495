"""``piste blender-addon --out piste_addon.zip``: write the Blender add-on as an installable zip.

The zip holds the folder ``piste_addon/`` (Blender: Edit > Preferences > Add-ons > Install...,
then enable "piste").  In a source checkout it is made from ``blender/piste_addon``; an installed
wheel carries it as package data (``piste/data/blender_addon.zip``, refreshed by ``make
blender-addon``; tests/blender/test_addon.py checks it matches the sources).  The same sources give
the same zip (fixed time stamps, sorted names).
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

#: the folder name inside the zip (the add-on's module name in Blender)
ADDON_NAME = "piste_addon"
_REPO_SOURCES = Path(__file__).resolve().parents[3] / "blender" / ADDON_NAME
PACKAGED_ZIP = Path(__file__).resolve().parents[1] / "data" / "blender_addon.zip"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, metavar="F.zip", help="the add-on zip to write")


def addon_sources() -> Path | None:
    """The checkout's ``blender/piste_addon`` folder, or None in an installed wheel."""
    return _REPO_SOURCES if (_REPO_SOURCES / "__init__.py").is_file() else None


def addon_zip_bytes(sources: Path | None = None) -> bytes:
    """The zip of the add-on's ``*.py`` files under ``piste_addon/`` (deterministic), or the
    packaged zip when there are no sources (an installed wheel)."""
    sources = sources or addon_sources()
    if sources is None:
        from piste.errors import ConfigError

        if not PACKAGED_ZIP.is_file():
            raise ConfigError(f"the Blender add-on is missing: neither {_REPO_SOURCES} nor {PACKAGED_ZIP}: "
                              "reinstall piste")
        return PACKAGED_ZIP.read_bytes()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(sources.glob("*.py")):
            info = zipfile.ZipInfo(f"{ADDON_NAME}/{p.name}", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, p.read_bytes())
    return buf.getvalue()


def run(args: argparse.Namespace) -> int:
    import sys

    from piste.errors import ConfigError
    from piste.formats.atomic import write_bytes_atomic

    out = Path(args.out)
    if out.suffix.lower() != ".zip":
        raise ConfigError(f"--out {args.out!r}: expected a .zip file name (Blender installs add-ons from a zip)")
    data = addon_zip_bytes()
    write_bytes_atomic(out, data)
    print(f"wrote {out} ({len(data)} bytes): Blender > Edit > Preferences > Add-ons > Install..., then enable "
          "'piste' (set 'piste executable' in its preferences)", file=sys.stderr)
    return 0
