"""``--allow-path DIR`` (repeatable), on every subcommand: folders the *user* allows the files a
command reads to name besides their own folder (issue 24).  A file never allows itself anything:
a scene's ``allow_paths`` key is an error.  The ``PISTE_ALLOW_PATHS`` environment variable
(``os.pathsep``-separated) does the same.  See :mod:`piste.formats.safe_io`."""

from __future__ import annotations

import argparse
import os

from piste.formats.safe_io import ALLOW_PATHS_ENV, set_user_allow_paths

__all__ = ["add_allow_path", "apply"]


def _folder(text: str) -> str:
    """argparse type: an existing folder (a usage error, exit status 2, otherwise)."""
    if not text or "\x00" in text or not os.path.isdir(os.path.expanduser(text)):
        raise argparse.ArgumentTypeError(f"expected an existing folder, got {text[:200]!r}")
    return text


def add_allow_path(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--allow-path", action="append", type=_folder, default=[], metavar="DIR",
                        help="a folder the files this command reads may also name (repeatable; "
                             f"also ${ALLOW_PATHS_ENV}). Without it a scene, model or world reads only "
                             "inside its own folder, through no symbolic link")


def apply(args: argparse.Namespace) -> None:
    """Make ``args.allow_path`` the process's user-allowed folders (none when the flag is absent)."""
    set_user_allow_paths(getattr(args, "allow_path", None) or (), "--allow-path")
