"""ruff and mypy, configured in pyproject.toml ([tool.ruff], [tool.mypy]), find nothing in src/piste.

The rule sets start lenient (pyflakes, pycodestyle's errors and closures over loop variables; mypy
with the numpy-inference codes off) and pass today, so any NEW finding fails here, naming the file,
line and rule.  Both tools come with the ``dev`` extra (pinned in constraints.txt).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def _tool(name: str) -> list[str]:
    if importlib.util.find_spec(name) is None:
        pytest.skip(f"{name} is not installed (pip install -e '.[dev]')")
    return [sys.executable, "-m", name]


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)


def test_ruff_finds_nothing():
    r = _run([*_tool("ruff"), "check", "--no-cache", "--output-format", "concise", "src/piste"])
    assert r.returncode == 0, "ruff findings (fix them; the rules are in pyproject.toml [tool.ruff]):\n" + r.stdout + r.stderr


def test_mypy_finds_nothing():
    r = _run([*_tool("mypy")])  # files, strictness and cache from pyproject.toml [tool.mypy]
    assert r.returncode == 0, "mypy findings (fix them; the settings are in pyproject.toml [tool.mypy]):\n" + r.stdout + r.stderr


def test_the_checks_can_fail(tmp_path):
    """A planted unused import, loop-variable closure and wrong call are reported under this config."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        "import os\n\n\n"
        "def f(a: int) -> int:\n    return a\n\n\n"
        "def g() -> list:\n    out = []\n    for i in range(3):\n        out.append(lambda: i)\n    return out\n\n\n"
        "f(1, 2)\n"
    )
    r = _run([*_tool("ruff"), "check", "--no-cache", "--config", str(PYPROJECT), "--output-format", "concise", str(bad)])
    assert r.returncode == 1 and "F401" in r.stdout and "B023" in r.stdout, r.stdout + r.stderr
    r = _run([*_tool("mypy"), "--config-file", str(PYPROJECT), "--no-incremental", str(bad)])
    assert r.returncode == 1 and "[call-arg]" in r.stdout, r.stdout + r.stderr


#: the packages and modules whose every function is annotated and checked strictly (pyproject.toml's
#: [[tool.mypy.overrides]] with disallow_untyped_defs): the list may grow, never shrink
STRICT_REQUIRED = (
    "piste.errors", "piste.scene_data", "piste.transforms", "piste.lighting", "piste.world",
    "piste.pipeline.build", "piste.pipeline.open_scene", "piste.pipeline.bundle_objects",
    "piste.formats.atomic", "piste.formats.bpt", "piste.formats.bundle_schema", "piste.formats.limits",
    "piste.formats.ssx.lightmap", "piste.formats.ssx.mpf_layout", "piste.formats.ssx.pbd", "piste.formats.ssx.ssh",
    "piste.formats.gltf.checks", "piste.formats.gltf.extensions", "piste.formats.gltf.schema", "piste.formats.gltf.units",
    "piste.formats.geotiff", "piste.formats.safe_io",
    "piste.terrain.bezier", "piste.terrain.fit", "piste.terrain.heightfield", "piste.terrain.stats",
    "piste.terrain.query", "piste.terrain.tiles",
    "piste.character.batches", "piste.character.lod", "piste.character.palette", "piste.character.pose", "piste.character.skeleton",
    "piste.character.strips", "piste.character.animation", "piste.character.model", "piste.character.morph",
    "piste.character.skinning", "piste.formats.ssx.synth",
    "piste.formats.ssx.multitool", "piste.formats.ssx.multitool_objects",
    "piste.formats.ssx.afl", "piste.formats.ssx.mpf", "piste.formats.ssx.mpf_encode", "piste.formats.ssx.mpf_model",
    "piste.formats.gltf.read", "piste.formats.gltf.write",
    "piste.formats.gltf", "piste.formats.ssx",  # whole packages: every module, and any new one
    "piste.formats.gltf.material",
    "piste.character.compress", "piste.character.retarget",
    "piste.character.rider", "piste.character.coverage",
    "piste.character",  # the whole package: every module, and any new one
    "piste.terrain.lod", "piste.terrain.net", "piste.terrain.cull",
    "piste.terrain.tessellate",
    "piste.formats.bundle",
    "piste.formats",  # the whole package: every module, and any new one
    # the runtime and the command layer, module by module (pipeline, render and commands still hold
    # lenient modules: preview, tiled_build, sources, the passes, scene_renderer, frame, window, ...)
    "piste.pipeline.cache", "piste.pipeline.default_scene", "piste.pipeline.ssx_synth", "piste.pipeline.object_atlas",
    "piste.pipeline.ssx_source", "piste.pipeline.characters", "piste.pipeline.furnish", "piste.pipeline.dask_build",
    "piste.pipeline.gltf_import", "piste.pipeline.tiles_source", "piste.pipeline.ssx_rider",
    "piste.pipeline.bundle_gltf", "piste.pipeline.tile_objects", "piste.pipeline.live", "piste.pipeline.ssx_level",
    "piste.pipeline.visibility", "piste.render.terrain_mode", "piste.render.sky_pass", "piste.render.video",
    "piste.render.dof", "piste.render.overlay", "piste.render.interlace", "piste.render.context", "piste.render.aa",
    "piste.render.occlusion", "piste.render.textures", "piste.render.trace", "piste.commands._paths", "piste.commands._numbers",
    "piste.commands.bake", "piste.commands.blender_addon", "piste.commands.export", "piste.commands.stats",
    "piste.commands.ssx", "piste.workers", "piste.graph", "piste.cli", "piste._jit", "piste.extras",
)


def _strict_patterns() -> list[str]:
    import tomllib

    conf = tomllib.loads(PYPROJECT.read_text())["tool"]["mypy"]
    out = []
    for o in conf.get("overrides", []):
        if o.get("disallow_untyped_defs") and o.get("check_untyped_defs") and "arg-type" in o.get("enable_error_code", ()):
            mods = o["module"]
            out += [mods] if isinstance(mods, str) else list(mods)
    return out


def _is_strict(module: str, patterns: list[str]) -> bool:
    # mypy's rules: "a.b" names one module, "a.b.*" the package a.b and everything under it
    return any(module == p or (p.endswith(".*") and (module == p[:-2] or module.startswith(p[:-1])))
               for p in patterns)


def test_the_strict_list_covers_the_typed_packages():
    """Every module of the typed packages is under the strict mypy settings (so the list cannot
    silently shrink, and a new module in a typed package is checked from its first commit)."""
    patterns = _strict_patterns()
    src = ROOT / "src"
    missing = []
    for name in STRICT_REQUIRED:
        base = src / name.replace(".", "/")
        files = sorted(base.rglob("*.py")) if base.is_dir() else [base.with_suffix(".py")]
        assert files and files[0].exists(), f"{name}: no such module or package under src/"
        for f in files:
            mod = ".".join(f.relative_to(src).with_suffix("").parts).removesuffix(".__init__")
            if not _is_strict(mod, patterns):
                missing.append(mod)
    assert not missing, ("modules of the typed packages left out of pyproject.toml's strict [[tool.mypy.overrides]] "
                         f"(disallow_untyped_defs, check_untyped_defs, the codes re-enabled): {missing}")


def test_the_strict_settings_can_fail(tmp_path):
    """An unannotated function is reported under the strict override (the same settings as a module
    of the typed API), and passes under the lenient global ones."""
    import tomllib

    conf = tomllib.loads(PYPROJECT.read_text())["tool"]["mypy"]
    strict = next(o for o in conf["overrides"] if "piste.world.*" in o["module"])
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "mod.py").write_text("def f(a, b=1):\n    return a + b\n")
    lines = ["[mypy]", "ignore_missing_imports = True",
             f"disable_error_code = {', '.join(conf['disable_error_code'])}", "", "[mypy-pkg.*]"]
    for k, v in strict.items():
        if k != "module":
            lines.append(f"{k} = {', '.join(v) if isinstance(v, list) else str(v)}")
    cfg = tmp_path / "mypy.ini"
    cfg.write_text("\n".join(lines) + "\n")
    r = _run([*_tool("mypy"), "--config-file", str(cfg), "--no-incremental", str(tmp_path / "pkg")])
    assert r.returncode == 1 and "[no-untyped-def]" in r.stdout, r.stdout + r.stderr
    cfg.write_text("\n".join(lines[:3]) + "\n")
    r = _run([*_tool("mypy"), "--config-file", str(cfg), "--no-incremental", str(tmp_path / "pkg")])
    assert r.returncode == 0, r.stdout + r.stderr
