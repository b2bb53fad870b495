"""Sphinx configuration of piste's documentation site (``make docs`` -> docs/_build/html)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(HERE))
os.environ.setdefault("MPLBACKEND", "Agg")

import piste  # noqa: E402

project = "piste"
author = "the piste developers"
copyright = "2026, the piste developers (MIT)"
release = piste.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinx_gallery.gen_gallery",
    "myst_parser",  # the user guide (docs/guide/*.md)
    "piste_docs",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
myst_heading_anchors = 3

templates_path = []
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip"]
html_theme = "alabaster"
html_math_renderer = "piste_text"  # no MathJax from a CDN: the site works offline
html_static_path = []
html_title = f"piste {release}"
html_theme_options = {
    "description": "The rendering system of SSX (GDC 2002), made real in Python",
    "fixed_sidebar": True,
}

autosummary_generate = True
# a package page documents what the package defines, not again what it re-exports from its modules
# (each object is described once, on its module's page, so cross-references are not ambiguous)
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_typehints = "description"
autodoc_mock_imports = []
napoleon_numpy_docstring = True
napoleon_google_docstring = False
# config.cache: sphinx-gallery's configuration holds functions (rebuilt every time, no harm);
# ref.python: numpydoc field names ("vertices : int") that several classes also have as attributes
# are ambiguous as cross-references (Sphinx links the first; nothing is broken)
suppress_warnings = ["autosummary.import_cycle", "config.cache", "ref.python"]

# Every example in examples/ is a gallery page; its pictures are the PNGs it writes into
# $PISTE_EXAMPLE_OUT (collected by piste_docs.example_scraper), and it still runs as a test.
EXAMPLE_OUT = HERE / "_build" / "example_out"
os.environ["PISTE_EXAMPLE_OUT"] = str(EXAMPLE_OUT)
os.environ.setdefault("PISTE_DATA", str(ROOT.parent / "shared" / "data"))  # examples find the test data here

from piste_docs import example_scraper  # noqa: E402

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/\d\d_",  # run every numbered example
    "ignore_pattern": r"scenes/",
    "image_scrapers": (example_scraper,),
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "plot_gallery": "True",
    "reset_argv": lambda gallery_conf, script_vars: [],
    "min_reported_time": 0,
}
