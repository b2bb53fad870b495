"""The package installs cleanly: a lean core, extras named when missing, the wheel in a clean venv."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _req_names(reqs):
    import re

    return {re.split(r"[<>=!~\[ ;]", r, maxsplit=1)[0].lower() for r in reqs}


def test_core_dependencies_are_only_what_the_numpy_cores_need():
    core = _req_names(PYPROJECT["project"]["dependencies"])
    # threadpoolctl: the terrain fit pins BLAS to one thread so tiled builds are byte-identical whatever
    # the threads or workers (terrain.heightfield.single_threaded, issue 26 item 7)
    assert core == {"numpy", "scipy", "pygltflib", "pillow", "tqdm", "meshoptimizer", "threadpoolctl"}
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert {"gl", "video", "docs", "dask", "dev", "all"} <= set(extras)
    assert {"moderngl", "pyglet"} <= _req_names(extras["gl"])
    assert "imageio-ffmpeg" in _req_names(extras["video"])
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    assert PYPROJECT["project"]["license"] == "MIT" and PYPROJECT["project"]["license-files"] == ["LICENSE"]


def test_the_version_is_written_once_and_the_package_is_typed():
    """pyproject.toml reads the version from ``piste.__version__`` (no second copy to drift); the
    installed metadata says the same; ``py.typed`` ships as package data; classifiers are there."""
    import importlib.metadata

    import piste

    project = PYPROJECT["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "piste.__version__"}
    assert importlib.metadata.version("piste") == piste.__version__
    assert (ROOT / "src" / "piste" / "py.typed").exists()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["piste"]
    assert "Typing :: Typed" in project["classifiers"]


def test_every_dependency_is_pinned_in_the_constraints_file():
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line and not line.startswith("#") and "==" in line:
            name, version = line.split("==", 1)
            pins[name.strip().lower().replace("_", "-")] = version.strip()
    deps = set(_req_names(PYPROJECT["project"]["dependencies"]))
    for extra in ("gl", "video", "dev"):
        deps |= _req_names(PYPROJECT["project"]["optional-dependencies"][extra])
    missing = sorted(d for d in deps if d.replace("_", "-") not in pins)
    assert not missing, f"constraints.txt lacks pins for {missing}: run `make lock`"


def test_core_modules_import_without_any_extra():
    """terrain, character, lighting and formats must not import OpenGL, windows or video."""
    code = (
        "import sys\n"
        "for m in ('moderngl', 'pyglet', 'imageio', 'imageio_ffmpeg', 'matplotlib'):\n"
        "    sys.modules[m] = None\n"
        "import piste.terrain, piste.character, piste.lighting, piste.formats\n"
        "from piste.cli import build_parser\n"
        "build_parser()\n"
        "print('ok')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr


@pytest.mark.parametrize("blocked, argv, extra", [
    ("moderngl", ["demo", "--size", "32", "24", "--no-progress"], "gl"),
])
def test_missing_extra_is_one_line_naming_it(tmp_path, blocked, argv, extra):
    code = (
        "import sys\n"
        f"sys.modules[{blocked!r}] = None\n"
        "from piste.cli import main\n"
        f"sys.exit(main({argv!r}))\n"
    )
    env = dict(os.environ, PISTE_CACHE_DIR=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env)
    assert r.returncode == 1, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines == [f"piste {argv[0]} needs the '{extra}' extra ({blocked} is not installed): pip install 'piste[{extra}]'"]


def test_video_needs_the_video_extra(tmp_path):
    from piste.errors import MissingExtraError
    from piste.extras import require

    code = "import sys\nsys.modules['imageio'] = None\nfrom piste.render.video import VideoWriter\nVideoWriter(sys.argv[1])\n"
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "v.mp4")], capture_output=True, text=True)
    assert r.returncode != 0 and "'video' extra" in r.stderr and "MissingExtraError" in r.stderr
    with pytest.raises(MissingExtraError, match=r"pip install 'piste\[gl\]'"):
        require("pyglet.this_does_not_exist", "a window")


@pytest.mark.slow
def test_wheel_installs_in_a_clean_venv_and_runs_from_any_folder(tmp_path):
    """Build the wheel, install it without extras (core imports, demo names the extra), then with
    [gl] (``piste demo`` renders from an unrelated folder).  Versions come from constraints.txt."""
    dist = tmp_path / "dist"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                        "-w", str(dist), str(ROOT)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = dist.glob("piste-*.whl")
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    py, piste = env_dir / "bin" / "python", env_dir / "bin" / "piste"
    pip = [str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check", "-c", str(ROOT / "constraints.txt")]
    r = subprocess.run([*pip, str(wheel)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["PISTE_CACHE_DIR"] = str(tmp_path / "cache")
    r = subprocess.run([str(py), "-c", "import piste.terrain, piste.character, piste.lighting; print('core ok')"],
                       capture_output=True, text=True, cwd=work, env=env)
    assert r.stdout.strip() == "core ok", r.stderr
    r = subprocess.run([str(piste), "demo", "--size", "64", "48", "--no-progress"], capture_output=True, text=True,
                       cwd=work, env=env)
    assert r.returncode == 1 and "pip install 'piste[gl]'" in r.stderr, r.stderr
    r = subprocess.run([*pip, f"{wheel}[gl]"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    r = subprocess.run([str(piste), "demo", "--size", "64", "48", "--no-progress", "--lighting", "placeholder"],
                       capture_output=True, text=True, cwd=work, env=env, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert (work / "out" / "demo.png").stat().st_size > 1000
