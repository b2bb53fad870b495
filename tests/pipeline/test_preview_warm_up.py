"""ScenePreview holds the background numba warm-up through its set-up and first frame (numba's
import holds the GIL; beside it a fresh process's first frame took ~0.13 s longer) and lets it
start with the next frame; released without a second frame, it does not start it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from piste import _jit
from piste.pipeline.ssx_synth import make_level
from piste.pipeline import load_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.preview import ScenePreview
from piste.pipeline.ssx_level import load_level



def fake_warm_up_state(monkeypatch) -> list:
    """Fresh warm-up state whose thread only records that it was started."""
    started = []

    class Thread:
        def __init__(self, target, name, daemon):
            self.name = name

        def start(self):
            started.append(self.name)

    monkeypatch.setattr(_jit, "HAVE_NUMBA", True)
    monkeypatch.setattr(_jit, "_THREAD", [None])
    monkeypatch.setattr(_jit, "_HOLDS", [0, False])
    monkeypatch.setattr(_jit, "threading", SimpleNamespace(Thread=Thread))
    return started


def _bundle(tmp_path):
    make_level(rows=2, cols=2, seed=1).write(tmp_path, "LV")
    lo, hi = load_level(tmp_path / "LV.pbd").net.bounds
    cx, cy = (np.asarray(lo[:2]) + np.asarray(hi[:2])) / 2
    scene = tmp_path / "s.toml"
    scene.write_text(f'terrain = {{ ssx_pbd = "LV.pbd" }}\n[render]\nsize = [32, 24]\n'
                     f'[[riders]]\nposition = [{cx}, {cy}]\n'
                     f'[[cameras]]\nname = "c"\neye = [{cx}, {cy - 9}, 10.0]\ntarget = [{cx}, {cy}, 3.0]\n')
    return load_bundle(build_scene(scene, use_cache=False).path)


def test_warm_up_waits_for_the_first_frame(tmp_path, gl, monkeypatch):
    b = _bundle(tmp_path)
    started = fake_warm_up_state(monkeypatch)
    p = ScenePreview(b, ctx=gl, shadows=False)
    try:
        _jit.warm_up_async()  # (what a kernel's ready() asks during set-up or the first frame)
        p.render()
        assert started == []
        p.render()
        assert started == ["piste-numba-warm-up"]
    finally:
        p.release()
    started = fake_warm_up_state(monkeypatch)
    q = ScenePreview(b, ctx=gl, shadows=False)
    _jit.warm_up_async()
    assert started == []
    q.release()  # never rendered (or `piste render`'s one frame): the hold goes, numba is not loaded
    assert started == []
    _jit.warm_up_async()  # the next ask starts it
    assert started == ["piste-numba-warm-up"]
