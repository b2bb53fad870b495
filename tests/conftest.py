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
    from piste.character import load_gltf

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
