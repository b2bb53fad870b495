"""``piste stats``: the talk's terrain statistics table (filled in by the terrain core)."""

from __future__ import annotations


def add_arguments(parser) -> None:
    parser.add_argument("net", nargs="?", help="a .bpt or .npz patch net (default: the default course)")
    parser.add_argument("--eye", nargs=3, type=float, metavar=("X", "Y", "Z"), help="camera position")
    parser.add_argument("--target", nargs=3, type=float, metavar=("X", "Y", "Z"), help="camera target")


def run(args) -> int:
    raise NotImplementedError
