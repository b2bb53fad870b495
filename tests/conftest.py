"""Shared test fixtures."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import pytest

DATA = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
GLTF_DIR = DATA / "gltf"
GLTF_FILES = sorted(p for p in GLTF_DIR.glob("*/*") if p.suffix in (".gltf", ".glb"))


@functools.lru_cache(maxsize=None)
def _load_gltf_cached(path: str):
    from piste.formats import load_gltf

    return load_gltf(path)


@pytest.fixture(scope="session")
def gltf_model():
    """``gltf_model(name)`` -> Model loaded (once per session) from ../shared/data/gltf/<name>/.

    Tests must not modify the returned model (copy arrays first).
    """

    def get(name: str):
        files = [p for p in GLTF_FILES if p.parent.name == name]
        if not files:
            pytest.skip(f"test model {name} not found in {GLTF_DIR}")
        return _load_gltf_cached(str(files[0]))

    return get


# ------------------------------------------------------------------------------------ OpenGL
# One headless context (EGL; Mesa llvmpipe without a GPU) for the whole session.  Tests that
# use it are skipped, with the reason, only when no context can be created at all; set
# PISTE_REQUIRE_GL=1 (CI) to make that a failure instead.


@pytest.fixture(scope="session")
def gl_context():
    from piste.errors import RenderError
    from piste.render.context import create_context

    try:
        ctx = create_context()
    except RenderError as exc:
        if os.environ.get("PISTE_REQUIRE_GL"):
            pytest.fail(f"PISTE_REQUIRE_GL is set but no OpenGL context: {exc}")
        pytest.skip(f"no headless OpenGL context can be created here: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture
def gl(gl_context):
    """The shared moderngl context; asserts there is no pending GL error before and after the test."""
    err = gl_context.error
    assert err == "GL_NO_ERROR", f"GL error {err} left over before the test"
    yield gl_context
    err = gl_context.error
    assert err == "GL_NO_ERROR", f"the test left GL error {err}"


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "gl" in getattr(item, "fixturenames", ()) or "gl_context" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.gl)


@pytest.fixture(scope="session")
def _piste_cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("piste-cache")


@pytest.fixture(autouse=True)
def piste_cache(_piste_cache_dir, monkeypatch):
    """``PISTE_CACHE_DIR`` pointed at a per-session temporary folder for every test (baked light maps
    and the built default scene land there, not in the user's ~/.cache); a test may point it
    elsewhere itself."""
    monkeypatch.setenv("PISTE_CACHE_DIR", str(_piste_cache_dir))
    return _piste_cache_dir


@pytest.fixture(scope="session", autouse=True)
def _numba_kernels_compiled_first():
    """Every numba kernel compiled (or loaded from numba's cache) once, in the main thread, before
    the first test, so no kernel's ``ready()`` starts the background warm-up in the middle of a test:
    numba compiles under ``warnings.catch_warnings``, which swaps the process-wide warning filters
    and is not thread-safe, and a warm-up thread compiling while a test entered and left
    ``catch_warnings`` / ``pytest.warns`` left that test's filters in force or lost its warnings
    (CI: ``test_scene_file_clips_from_with_bone_map`` "DID NOT WARN", then a RetargetWarning raised
    as an error inside ``pytest.warns``).  ~6 s without numba's cache; tests of the warm-up itself
    patch ``piste._jit`` as before."""
    from piste import _jit

    _jit.warm_up()
    yield


@pytest.fixture(autouse=True)
def _numba_warm_up_joined():
    """A test that started the background numba warm-up (``piste._jit.warm_up_async``, e.g. a
    preview) waits for it before the next test starts: numba compiles under
    ``warnings.catch_warnings``, which swaps the process-wide warning filters and is not thread-safe,
    so a warm-up still compiling could swallow the warnings a later ``pytest.warns`` expects (seen
    in CI: ``test_scene_file_clips_from_with_bone_map`` "DID NOT WARN")."""
    yield
    import threading

    for t in threading.enumerate():
        if t.name == "piste-numba-warm-up" and t.is_alive():
            t.join()
