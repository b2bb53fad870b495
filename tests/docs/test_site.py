"""The documentation site builds and reads like a user would see it: pages opened in headless
Chromium (Debian's ``chromium`` + ``chromium-driver``), screenshots taken, no broken links, no
missing images, no JavaScript errors."""

from __future__ import annotations

import html.parser
import os
import shutil
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote, urldefrag, urlparse

import pytest

ROOT = Path(__file__).resolve().parents[2]
REQUIRE = os.environ.get("PISTE_REQUIRE_TOOLS") == "1"

TALK_PAGES = ["characters", "faces", "terrain", "lighting", "scene", "pipelines"]


def _need(what: str, ok: bool):
    if not ok:
        if REQUIRE:
            pytest.fail(f"{what} is required (PISTE_REQUIRE_TOOLS=1) but missing: run tools/setup-test-tools.sh")
        pytest.skip(f"{what} not installed (tools/setup-test-tools.sh installs it)")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """Build the site once into a temporary folder (the same command as ``make docs``)."""
    pytest.importorskip("sphinx_gallery") if not REQUIRE else None
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, MPLBACKEND="Agg", PISTE_CACHE_DIR=str(out / "cache"))
    r = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-q", "-W", "--keep-going", str(ROOT / "docs"),
                        str(out / "html")],
                       capture_output=True, text=True, env=env, cwd=ROOT, timeout=1200)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    return out / "html"


class _Refs(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.images = [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "a" and a.get("href"):
            self.links.append(a["href"])
        if tag == "img" and a.get("src"):
            self.images.append(a["src"])


def _local(page: Path, ref: str):
    url = urlparse(ref)
    if url.scheme or ref.startswith(("mailto:", "#", "//")):
        return None
    path, _ = urldefrag(unquote(url.path))
    return (page.parent / path).resolve() if path else None


@pytest.mark.slow
def test_every_talk_section_has_a_page_with_generated_figures(site):
    for name in TALK_PAGES:
        page = site / "talk" / f"{name}.html"
        assert page.exists(), name
        p = _Refs()
        p.feed(page.read_text())
        if name != "pipelines":
            assert p.images, f"talk page {name} has no figures"
    terrain = (site / "talk" / "terrain.html").read_text()
    for fig in ("tess_4.png", "tess_6.png", "tess_8.png", "tess_dynamic.png", "scene_lod.png"):
        assert fig in terrain
    assert "29.68" in terrain and "average polygons per patch" in terrain  # the table beside the talk's
    lighting = (site / "talk" / "lighting.html").read_text()
    for fig in ("ps2_cd.png", "ps2_cl.png", "ps2_as.png", "ps2_cs.png", "ps2_result.png", "lightmap_point_8.png",
                "lightmap_bilinear_16.png"):
        assert fig in lighting


@pytest.mark.slow
def test_every_example_is_a_gallery_page_with_its_output(site):
    examples = sorted(p.stem for p in (ROOT / "examples").glob("[0-9][0-9]_*.py"))
    assert examples
    for name in examples:
        page = site / "auto_examples" / f"{name}.html"
        assert page.exists(), f"example {name} has no gallery page"
    # the examples that write pictures show them
    for name in ("04_render_frame", "05_bake_lightmap"):
        p = _Refs()
        p.feed((site / "auto_examples" / f"{name}.html").read_text())
        assert any("sphx_glr" in src for src in p.images), f"{name}: no picture"


@pytest.mark.slow
def test_api_cli_and_formats_are_documented(site):
    cli = (site / "cli.html").read_text()
    from piste.cli import COMMANDS

    for name in COMMANDS:
        assert f"piste {name}" in cli, name
    api = (site / "api.html").read_text()
    for sub in ("piste.terrain", "piste.character", "piste.lighting", "piste.formats", "piste.render"):
        assert sub in api
    assert (site / "_autosummary" / "piste.terrain.html").exists()
    formats = (site / "formats.html").read_text()
    for title in ("Scene files", "Bundles", "Lights files"):
        assert title in formats


@pytest.mark.slow
def test_no_broken_links_or_missing_images(site):
    broken = []
    for page in site.rglob("*.html"):
        p = _Refs()
        p.feed(page.read_text(errors="replace"))
        for ref in p.links + p.images:
            target = _local(page, ref)
            if target is not None and not target.exists():
                broken.append(f"{page.relative_to(site)} -> {ref}")
    assert not broken, "\n".join(broken[:40])


@pytest.mark.slow
def test_pages_in_headless_chromium(site, tmp_path):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_bin = shutil.which("chromedriver")
    _need("chromium + chromedriver (Debian: chromium chromium-driver)", bool(chromium and driver_bin))
    webdriver = pytest.importorskip("selenium.webdriver") if not REQUIRE else __import__(
        "selenium.webdriver", fromlist=["webdriver"])
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1200,900"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    drv = webdriver.Chrome(service=Service(driver_bin), options=opts)
    try:
        pages = [site / "index.html", site / "talk" / "lighting.html", site / "talk" / "terrain.html",
                 site / "auto_examples" / "index.html", site / "cli.html"]
        for page in pages:
            drv.get(page.as_uri())
            assert drv.title, page
            bad = drv.execute_script(
                "return Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src);")
            assert not bad, f"{page.name}: images that did not load: {bad}"
            errors = [e for e in drv.get_log("browser") if e["level"] == "SEVERE"]
            assert not errors, f"{page.name}: JavaScript/console errors: {errors}"
        drv.get((site / "index.html").as_uri())
        assert drv.save_screenshot(str(tmp_path / "index.png"))
        drv.get((site / "talk" / "lighting.html").as_uri())
        assert drv.save_screenshot(str(tmp_path / "talk_lighting.png"))
    finally:
        drv.quit()
    from PIL import Image
    import numpy as np

    for shot in ("index.png", "talk_lighting.png"):
        img = np.asarray(Image.open(tmp_path / shot).convert("RGB"))
        assert img.shape[0] > 400 and img.shape[1] > 800 and img.std() > 10, f"{shot} looks blank"
    out = os.environ.get("PISTE_DOCS_SCREENSHOTS")
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        for shot in ("index.png", "talk_lighting.png"):
            shutil.copyfile(tmp_path / shot, Path(out) / shot)
