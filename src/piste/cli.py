"""The ``piste`` command line.

Each subcommand lives in ``piste.commands.<name>`` with two functions, ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported lazily so that ``piste stats`` never loads OpenGL.

Exit status: 0 done, 1 a runtime error (a :class:`piste.errors.PisteError`, a missing extra, an
unwritable path: one line on stderr), 2 a usage error (argparse), 130 interrupted.  ``-v``/``-q``
set the level of the ``piste`` logger (INFO by default: what the library reports as it works).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import NoReturn

from piste import __version__
from piste.commands import _numbers as N
from piste.errors import MissingExtraError, PisteError, describe_os_error

#: exit status of a runtime error (a usage error is argparse's 2)
EXIT_ERROR = 1

#: subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("piste.commands.demo", "render the default course (PNG, and MP4 with --frames)"),
    "stats": ("piste.commands.stats", "print the talk's terrain statistics table for a net and camera"),
    "bake": ("piste.commands.bake", "bake per-patch light maps with terrain shadows into an atlas"),
    "view": ("piste.commands.view", "fly over the default course in a window (LOD follows the camera)"),
    "build": ("piste.commands.build", "pre-process a scene (.toml) into one .piste bundle (cached, byte-identical)"),
    "render": ("piste.commands.render", "render a scene (.toml or .piste) from one of its cameras (PNG, MP4)"),
    "export": ("piste.commands.export", "export a scene (.toml or .piste) to glTF (.glb/.gltf): terrain, riders, objects, lights"),
    "ssx": ("piste.commands.ssx", "SSX Tricky levels (.pbd): info, render, view, bake light maps, convert, make, import"),
    "mpf": ("piste.commands.mpf", "SSX Tricky rider models (.mpf): info, encode a piste rider, export to glTF, copy"),
    "blender-addon": ("piste.commands.blender_addon", "write the Blender add-on (author scenes, live preview, SSX import) as a zip"),
}


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr, exit status 2: ``piste demo:
    error: argument --seed: expected an integer in [0, 4294967295], got '-1' (piste demo -h: usage)``
    (subcommands' parsers are of this class too: add_subparsers takes the parent's class)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} ({self.prog} -h: usage)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="piste", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"piste {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="say more: the library's debug messages")
    parser.add_argument("-q", "--quiet", dest="quiet_log", action="count", default=0,
                        help="only warnings and errors (-qq: errors only)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        p.set_defaults(_module=module)
        importlib.import_module(module).add_arguments(p)
        importlib.import_module("piste.commands._paths").add_allow_path(p)  # --allow-path DIR (issue 24)
        if name in ("demo", "render", "view"):  # the commands pass it to the runtime (lod_morph=)
            p.add_argument("--lod-morph", choices=("on", "off"), default=None,
                           help="geomorph terrain vertices between LOD levels (default: on, or the scene file's "
                                "[lod] morph); off: the talk's exact behaviour")
            p.add_argument("--aa", choices=("off", "msaa2", "msaa4", "msaa8", "fxaa"), default=None,
                           help="anti-aliasing: multisampling (msaaN, capped at the GL's maximum: 4 on llvmpipe) "
                                "or the FXAA post pass (default: off, or the scene file's [render] aa)")
            p.add_argument("--dof", type=N.focus_aperture, default=None, metavar="FOCUS_M:APERTURE",
                           help="depth of field: focus distance and lens radius in metres, e.g. 8:0.1 (a post pass; "
                                "default: none, or the scene file's [render] dof)")
            if name != "view":  # (a window shows the frame at its own size)
                p.add_argument("--supersample", type=importlib.import_module("piste.commands._numbers").integer(1, 8),
                               default=1, metavar="N", help="draw at N x N the size and box-filter down (the "
                               "anti-aliasing reference; default 1)")
                p.add_argument("--interlace", action="store_true",
                               help="video as a PS2 on a television showed it: each frame's even lines from one field, "
                                    "its odd lines from the next, half a frame later (fields at 2 x --fps)")
                p.add_argument("--flicker-filter", action="store_true",
                               help="with --interlace: each field filtered [1 2 1] / 4 down its columns before weaving "
                                    "(the PS2 games' cure for interlace flicker)")
            p.add_argument("--soft-shadows", action="store_const", const=True, default=None,
                           help="soft rider shadows: percentage-closer soft shadows from the real sun's 0.27 degree "
                                "disc (default: off, the talk's hard shadows, or the scene file's [render] soft_shadows)")
            p.add_argument("--occlusion", choices=("on", "off"), default=None,
                           help="cull the terrain patches and objects the near terrain hides (a software "
                                "hierarchical-Z; the same pixels; default: off, or the scene file's [render] occlusion)")
            p.add_argument("--trace", metavar="FILE.json", default=None,
                           help="write a Chrome / Perfetto trace (ui.perfetto.dev) of every frame: CPU spans per step, "
                                "GPU spans per pass from GL timer queries")
    return parser


def log_level(verbose: int, quiet: int) -> int:
    """The ``piste`` logger's level for ``-v``/``-q`` counts: INFO by default, DEBUG with ``-v``,
    WARNING with ``-q``, ERROR with ``-qq``."""
    steps = (logging.DEBUG, logging.INFO, logging.WARNING, logging.ERROR)
    return steps[max(0, min(len(steps) - 1, 1 - verbose + quiet))]


def _log_to_stderr(level: int) -> tuple[logging.Handler, int]:
    """Messages of the ``piste`` logger go to stderr as ``piste: message``; returns the handler and
    the logger's previous level (restored when :func:`main` returns, so that calling ``main`` twice
    does not print twice)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("piste: %(message)s"))
    logger = logging.getLogger("piste")
    previous = logger.level
    logger.addHandler(handler)
    logger.setLevel(level)
    return handler, previous


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handler, previous_level = _log_to_stderr(log_level(args.verbose, args.quiet_log))
    try:
        importlib.import_module("piste.commands._paths").apply(args)  # the folders the user allows
        return int(importlib.import_module(args._module).run(args) or 0)
    except MissingExtraError as exc:
        print(f"piste {args.command} needs the '{exc.extra}' extra ({exc.module} is not installed): "
              f"pip install 'piste[{exc.extra}]'", file=sys.stderr)
        return EXIT_ERROR
    except PisteError as exc:
        print(f"piste {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:  # unwritable or full output / cache, a vanished input: one line naming the path
        print(f"piste {args.command}: error: {describe_os_error(exc)}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    finally:
        logging.getLogger("piste").removeHandler(handler)
        logging.getLogger("piste").setLevel(previous_level)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
