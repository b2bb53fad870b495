"""piste's cache folder is decided in one place (piste.pipeline.cache.cache_root): $PISTE_CACHE_DIR,
else $XDG_CACHE_HOME/piste, else ~/.cache/piste; the default scene and the demo's light maps use it."""

from __future__ import annotations

from pathlib import Path

import pytest

from piste.extras import ENVIRONMENT, child_environment, environ
from piste.pipeline.cache import cache_root
from piste.pipeline.default_scene import default_scene_path


def test_piste_cache_dir_wins(monkeypatch, tmp_path):
    monkeypatch.setenv("PISTE_CACHE_DIR", str(tmp_path / "mine"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "mine"


def test_xdg_cache_home_is_honoured(monkeypatch, tmp_path):
    monkeypatch.delenv("PISTE_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "piste"
    assert default_scene_path(0).parent == tmp_path / "xdg" / "piste" / "scenes"


@pytest.mark.parametrize("xdg", [None, "", "relative/cache"])
def test_home_cache_without_a_usable_xdg_cache_home(monkeypatch, tmp_path, xdg):
    """Unset, empty or relative (the XDG spec says to ignore a relative path): ~/.cache/piste."""
    monkeypatch.delenv("PISTE_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    if xdg is None:
        monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    else:
        monkeypatch.setenv("XDG_CACHE_HOME", xdg)
    assert cache_root() == tmp_path / ".cache" / "piste"


def test_only_listed_variables_are_read_and_child_environment_restores(monkeypatch):
    with pytest.raises(KeyError, match="ENVIRONMENT"):
        environ("PISTE_SOMETHING_UNLISTED")
    assert {"PISTE_CACHE_DIR", "XDG_CACHE_HOME", "PISTE_NO_NUMBA"} <= set(ENVIRONMENT)
    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    import os

    with child_environment({"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}):
        assert os.environ["OMP_NUM_THREADS"] == "1" and os.environ["MKL_NUM_THREADS"] == "1"
    assert os.environ["OMP_NUM_THREADS"] == "7" and "MKL_NUM_THREADS" not in os.environ
    assert isinstance(cache_root(), Path)
