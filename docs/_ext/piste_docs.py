"""Sphinx extension for piste's docs: talk figures made at build time, the CLI reference from the
argument parsers, and an image scraper that shows what each example writes.

Nothing here is a stored picture: ``builder-inited`` runs ``docs/figures.py`` into
``docs/_generated/figures`` and writes ``docs/_generated/cli.rst`` from ``piste.cli``.
"""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
GENERATED = HERE / "_generated"


# ----------------------------------------------------------------------------- the CLI reference
def _usage(parser: argparse.ArgumentParser) -> str:
    return parser.format_usage().strip()


def cli_rst() -> str:
    """reST for every ``piste`` subcommand: usage, description and each option's help."""
    from piste.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    lines = ["Command line", "============", "",
             "Generated from the argument parsers in :mod:`piste.cli` and ``piste.commands.*`` at build time.", ""]
    for name, p in sub.choices.items():
        title = f"piste {name}"
        lines += [title, "-" * len(title), "", (p.description or "").strip(), "", ".. code-block:: text", ""]
        lines += ["   " + ln for ln in _usage(p).splitlines()] + [""]
        rows = []
        for action in p._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            flags = ", ".join(action.option_strings) or action.dest
            meta = ""
            if action.option_strings and action.nargs != 0:
                meta = " " + (" ".join(action.metavar) if isinstance(action.metavar, tuple)
                              else str(action.metavar or action.dest.upper()))
            choices = f" (one of: {', '.join(map(str, action.choices))})" if action.choices else ""
            help_ = (action.help or "").replace("%(default)s", str(action.default)).replace("%%", "%")
            rows.append((f"``{flags}{meta}``", (help_ + choices).replace("\n", " ").strip() or "-"))
        if rows:
            lines += [".. list-table::", "   :widths: 35 65", ""]
            for a, b in rows:
                lines += [f"   * - {a}", f"     - {b}"]
            lines.append("")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- file formats
#: (title, module) of every file format piste reads or writes; modules not present yet are skipped
FORMATS = [
    ("Scene files (.toml)", "piste.world.scene_file"),
    ("Lights files (.toml)", "piste.lighting.lights"),
    ("Bundles (.piste)", "piste.formats.bundle"),
    ("Bézier patch text (.bpt)", "piste.formats.bpt"),
    ("glTF 2.0 import", "piste.formats.gltf.read"),
    ("glTF 2.0 export", "piste.formats.gltf.write"),
    ("GeoTIFF height fields", "piste.formats.geotiff"),
    ("Tiled nets", "piste.terrain.tiles"),
    ("SSX Tricky levels (.pbd)", "piste.formats.ssx.pbd"),
    ("SSX texture banks (.ssh)", "piste.formats.ssx.ssh"),
    ("SSX Multitool projects (Patches.json)", "piste.formats.ssx.multitool"),
    ("SSX Multitool instances, splines, models (Instances/Splines/Models.json)",
     "piste.formats.ssx.multitool_objects"),
    ("SSX Tricky rider models (.mpf)", "piste.formats.ssx.mpf"),
]


def formats_rst() -> str:
    import importlib

    lines = ["File formats", "============", "",
             "Every format piste reads or writes, documented from its module (generated at build time).", ""]
    for title, module in FORMATS:
        try:
            importlib.import_module(module)
        except ImportError:
            continue
        lines += [title, "-" * len(title), "", f".. automodule:: {module}", "   :no-members:", "   :no-index:", "",
                  f"API: :mod:`{module}`.", ""]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- the examples' pictures
_seen: dict[str, float] = {}


def example_scraper(block, block_vars, gallery_conf, **kwargs):
    """sphinx-gallery image scraper: the PNGs an example wrote into $PISTE_EXAMPLE_OUT since the last call."""
    from sphinx_gallery.scrapers import figure_rst

    out = Path(os.environ["PISTE_EXAMPLE_OUT"])
    found = []
    for p in sorted(out.rglob("*.png")) if out.exists() else []:
        stamp = p.stat().st_mtime
        if _seen.get(str(p)) != stamp:
            _seen[str(p)] = stamp
            found.append(p)
    paths = []
    for p, target in zip(found, block_vars["image_path_iterator"]):
        shutil.copyfile(p, target)
        paths.append(target)
    return figure_rst(paths, gallery_conf["src_dir"])


# ----------------------------------------------------------------------------- math without a CDN
# The site must work offline (CI and users behind firewalls): formulas are rendered as HTML text
# (Unicode symbols, <sub>/<sup>) instead of MathJax from a CDN.
_SYMBOLS = {r"\times": "×", r"\sum": "Σ", r"\cdot": "·", r"\leq": "≤", r"\geq": "≥", r"\max": "max",
            r"\min": "min", r"\frac": "", r"\left": "", r"\right": "", r"\,": " ", r"\;": " ", r"\ ": " "}


def math_html(latex: str) -> str:
    import html
    import re

    t = latex
    for k, v in _SYMBOLS.items():
        t = t.replace(k, v)
    t = re.sub(r"\\(mathrm|mathbf|text|operatorname)\{([^{}]*)\}", r"\2", t)
    t = html.escape(t)
    t = re.sub(r"_\{([^{}]*)\}", r"<sub>\1</sub>", t)
    t = re.sub(r"_([A-Za-z0-9*])", r"<sub>\1</sub>", t)
    t = re.sub(r"\^\{([^{}]*)\}", r"<sup>\1</sup>", t)
    t = re.sub(r"\^([A-Za-z0-9*])", r"<sup>\1</sup>", t)
    return t.replace("{", "").replace("}", "")


def _visit_inline(self, node):
    self.body.append(f'<span class="math">{math_html(node.astext())}</span>')
    from docutils import nodes

    raise nodes.SkipNode


def _visit_block(self, node):
    self.body.append(f'<div class="math"><p>{math_html(node.astext())}</p></div>')
    from docutils import nodes

    raise nodes.SkipNode


# ----------------------------------------------------------------------------- hooks
def _generate(app) -> None:
    import sys

    sys.path.insert(0, str(HERE))
    import figures

    GENERATED.mkdir(exist_ok=True)
    (GENERATED / "cli.rst").write_text(cli_rst())
    (GENERATED / "formats.rst").write_text(formats_rst())
    only = os.environ.get("PISTE_DOCS_FIGURES")  # e.g. "tessellation,stats" for a quick build
    took = figures.main(GENERATED / "figures", only.split(",") if only else None)
    for name, seconds in took.items():
        print(f"piste docs: figure set {name!r} made in {seconds:.1f} s")


def setup(app):
    app.connect("builder-inited", _generate)
    app.add_html_math_renderer("piste_text", (_visit_inline, None), (_visit_block, None))
    return {"version": "1", "parallel_read_safe": True}
