"""The packages re-export their names lazily (PEP 562, piste._lazy_exports): a bundle render imports no
build, bake, glTF, SSX or Dask module, and every public name still resolves.

No timing here (speed lives in benchmarks/bench_build.py): what is checked is *which* modules a
fresh process has imported.
"""

from __future__ import annotations

import ast
import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

#: the packages whose ``__init__`` re-exports lazily
LAZY_PACKAGES = ("piste.pipeline", "piste.render", "piste.formats", "piste.formats.ssx", "piste.formats.gltf",
                 "piste.character",
                 "piste.lighting", "piste.terrain", "piste.world")

#: what the bundle runtime imports (benchmarks/bench_build.py's fresh process: load_bundle, ScenePreview,
#: create_context)
RUNTIME = ("piste.pipeline.bundle_objects", "piste.pipeline.preview", "piste.render.context")

#: modules a bundle render never uses: the build and its steps, the light-map baker, the glTF importer,
#: the SSX readers, tiled / Dask builds, terrain statistics, retargeting
NOT_IMPORTED = ("piste.pipeline.build", "piste.pipeline.cache", "piste.pipeline.gltf_import", "piste.pipeline.live",
                "piste.pipeline.default_scene", "piste.pipeline.tiled_build", "piste.pipeline.dask_build",
                "piste.pipeline.ssx_level", "piste.pipeline.ssx_rider", "piste.lighting.baker", "piste.lighting.gi",
                "piste.formats.ssx", "piste.formats.geotiff", "piste.formats.gltf.read", "piste.formats.gltf.write",
                "piste.world.scene_file",
                "piste.render.streaming", "piste.render.ssx_pass", "piste.render.window", "piste.terrain.tiles",
                # the talk's statistics table; bone maps and retargeting (the model needs only the coverage check)
                "piste.terrain.stats", "piste.character.retarget",
                # (OpenSSL) hashes bundle members when written or verified and keys bakes: neither is a render
                "hashlib",
                # the glTF extension decoders (a bundle's rider material is a MaterialInfo: formats.gltf.material)
                "piste.formats.gltf.extensions",
                # (stdlib) atomic writes' and videos' temporary files, find_library's ldconfig run: a render
                # writes no temp file and names its GL libraries (piste.render.context.EGL_LIBRARIES)
                "tempfile", "subprocess", "ctypes.util",
                # (stdlib, with shutil, bz2 and lzma: ~2.5 ms) bundles and the shipped .npz files are read
                # through piste.formats.ziplite; zipfile only writes them or reads an archive it does not
                "zipfile",
                # the character step's batcher and stripifier and the glTF material (a bundle stores their
                # results; a bundle rider without a material of its own makes none)
                "piste.character.batches", "piste.character.strips", "piste.formats.gltf.material",
                # interlaced frames, MP4 output and the occlusion pass: only when asked for
                "piste.render.interlace", "piste.render.video", "piste.render.occlusion",
                # making a net from a height field or a .bpt file (a bundle stores its net)
                "piste.terrain.heightfield", "piste.terrain.fit", "piste.formats.bpt",
                "dask", "distributed",
                "scipy", "tifffile")


def _imported_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True, timeout=120)
    return set(json.loads(out.stdout.splitlines()[-1]))


def test_a_bundle_render_imports_no_build_bake_gltf_ssx_or_dask_module():
    mods = _imported_after("\n".join(f"import {m}" for m in RUNTIME))
    assert set(RUNTIME) <= mods
    loaded = sorted(m for m in mods if any(m == bad or m.startswith(bad + ".") for bad in NOT_IMPORTED))
    assert not loaded, f"the bundle runtime imported {loaded}"


def test_importing_piste_and_the_cli_imports_no_subpackage_module():
    mods = _imported_after("import piste, piste.cli")
    # piste.commands._numbers: the checked argparse number types (argparse and math only) that the
    # CLI's shared flags use
    allowed = ("piste.cli", "piste.errors", "piste.commands", "piste.commands._numbers")
    extra = sorted(m for m in mods if m.startswith("piste.") and m not in allowed)
    assert not extra, f"piste / piste.cli import only themselves, piste.errors and the number types: {extra}"


def test_the_check_sees_an_eager_import():
    """The runtime check above can fail: asking a package for a build name imports the build."""
    mods = _imported_after("import piste.pipeline\npiste.pipeline.build_scene")
    assert "piste.pipeline.build" in mods
    mods = _imported_after("import piste.render")
    assert "piste.render.streaming" not in mods and "piste.render.scene_renderer" not in mods


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_every_public_name_resolves_and_the_type_checking_imports_agree(package):
    """``__all__`` resolves name by name, ``dir()`` lists it, ``from package import *`` works, an unknown
    name is an AttributeError, and the ``if TYPE_CHECKING:`` imports name exactly the lazy names
    (what type checkers and tests/test_architecture.py see is what runs)."""
    mod = importlib.import_module(package)
    assert len(mod.__all__) == len(set(mod.__all__)) > 0
    for name in mod.__all__:
        value = getattr(mod, name)
        assert not (isinstance(value, type(sys)) and value.__name__ == f"{package}.{name}"), \
            f"{package}.{name} is the submodule, not the re-exported name"
        assert name in dir(mod)
    ns: dict = {}
    exec(f"from {package} import *", ns)
    assert set(mod.__all__) <= set(ns)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        getattr(mod, "no_such_name")
    path = SRC / Path(*package.split(".")) / "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    static = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(package + "."):
            static |= {a.asname or a.name for a in node.names}
    assert static == set(mod.__all__)


def test_a_name_that_is_also_a_submodule_stays_the_function():
    """``piste.character.palette`` / ``piste.terrain.stats`` / ``piste.terrain.tessellate`` are both a
    submodule and a function: importing the submodule first must not make the package's name the module."""
    code = ("import piste.character.palette, piste.terrain.stats, piste.terrain.tessellate\n"
            "from piste.character import palette\nfrom piste.terrain import stats, tessellate\n"
            "assert callable(palette) and callable(stats) and callable(tessellate)\n"
            "assert palette.__module__ == 'piste.character.palette' and stats.__module__ == 'piste.terrain.stats'\n")
    _imported_after(code)
