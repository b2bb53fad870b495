"""The build's ``shadow`` step: the sun visibility stored in the bundle, used by the runtime (same picture)."""

from __future__ import annotations

import dataclasses

import numpy as np

from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.preview import ScenePreview
from piste.render import scene_renderer
from piste.render.shadow_pass import sun_visibility
from piste.world.scene import sun_light
from tests.pipeline.conftest import RIDER, SMALL_SCENE


def _low_sun(small_scene):
    """The small scene with a low sun behind the hill (part of the terrain in its shadow)."""
    text = SMALL_SCENE.format(riders=RIDER, extra="").replace("direction = [0.3, 0.6, -0.6]",
                                                              "direction = [0.1, 0.95, -0.12]")
    return small_scene(text=text)


def test_bundle_stores_the_sun_visibility_exactly(small_scene):
    r = build_scene(_low_sun(small_scene))
    assert "shadow" in r.steps and not r.steps["shadow"]["cached"]
    b = load_bundle(r.path)
    sun = sun_light(b.lights)
    f, rect = sun_visibility(b.net, sun.direction)
    got = b.sun_visibility(sun.direction)
    assert got is not None
    assert got[0].dtype == np.float32 and np.array_equal(got[0], f)
    assert got[1] == tuple(rect)
    assert 0.0 < float(f.mean()) < 1.0  # the hill shadows part of the terrain
    # another sun: not this array (the runtime computes its own)
    assert b.sun_visibility(np.asarray(sun.direction) * [1.0, -1.0, 1.0]) is None
    # cached on a rebuild, bundle unchanged
    again = build_scene(r.path.with_suffix(".toml"))
    assert again.steps["shadow"]["cached"]
    assert again.path.read_bytes() == r.path.read_bytes()


def test_runtime_uses_the_stored_field_with_the_same_picture(small_scene, gl, monkeypatch):
    b = load_bundle(build_scene(_low_sun(small_scene)).path)
    ref = ScenePreview(b, size=(96, 64), ctx=gl)  # computes nothing: the bundle's field
    try:
        a = ref.render(b.camera())
    finally:
        ref.release()
    # a bundle without the step (built before it existed): computed at set-up, the same pixels
    old = dataclasses.replace(b, arrays={k: v for k, v in b.arrays.items() if not k.startswith("shadow/")},
                              manifest={k: v for k, v in b.manifest.items() if k != "shadow"}, _cache={})
    calls = []
    real = scene_renderer.sun_visibility

    def counting(*args, **kw):
        calls.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(scene_renderer, "sun_visibility", counting)
    p = ScenePreview(old, size=(96, 64), ctx=gl)
    try:
        assert calls == [1]
        assert np.array_equal(p.render(old.camera()), a)
    finally:
        p.release()
    calls.clear()
    p = ScenePreview(b, size=(96, 64), ctx=gl)
    try:
        assert calls == []  # the stored field was used
    finally:
        p.release()
