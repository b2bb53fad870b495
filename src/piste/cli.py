"""The ``piste`` command line.

Each subcommand lives in ``piste.commands.<name>`` with two functions, ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported lazily so that ``piste stats`` never loads OpenGL.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from piste.errors import MissingExtraError, PisteError, describe_os_error

#: subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("piste.commands.demo", "render the default course (PNG, and MP4 with --frames)"),
    "stats": ("piste.commands.stats", "print the talk's terrain statistics table for a net and camera"),
    "bake": ("piste.commands.bake", "bake per-patch light maps with terrain shadows into an atlas"),
    "view": ("piste.commands.view", "fly over the default course in a window (LOD follows the camera)"),
    "build": ("piste.commands.build", "pre-process a scene (.toml) into one .piste bundle (cached, byte-identical)"),
    "render": ("piste.commands.render", "render a scene (.toml or .piste) from one of its cameras (PNG, MP4)"),
    "export": ("piste.commands.export", "export a scene (.toml or .piste) to glTF (.glb/.gltf): terrain, riders, objects, lights"),
    "ssx": ("piste.commands.ssx", "SSX Tricky levels (.pbd): info, render, view, bake light maps, convert, make"),
    "mpf": ("piste.commands.mpf", "SSX Tricky rider models (.mpf): info, encode a piste rider, export to glTF, copy"),
}


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr, exit status 2: ``piste demo:
    error: argument --seed: expected an integer in [0, 4294967295], got '-1' (piste demo -h: usage)``
    (subcommands' parsers are of this class too: add_subparsers takes the parent's class)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} ({self.prog} -h: usage)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="piste", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        p.set_defaults(_module=module)
        importlib.import_module(module).add_arguments(p)
        if name in ("demo", "render", "view"):  # the commands pass it to the runtime (lod_morph=)
            p.add_argument("--lod-morph", choices=("on", "off"), default=None,
                           help="geomorph terrain vertices between LOD levels (default: on, or the scene file's "
                                "[lod] morph); off: the talk's exact behaviour")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except MissingExtraError as exc:
        print(f"piste {args.command} needs the '{exc.extra}' extra ({exc.module} is not installed): "
              f"pip install 'piste[{exc.extra}]'", file=sys.stderr)
        return 2
    except PisteError as exc:
        print(f"piste {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # unwritable or full output / cache, a vanished input: one line naming the path
        print(f"piste {args.command}: error: {describe_os_error(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
