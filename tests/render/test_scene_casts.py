"""Different riders in one scene: the default rider plus glTF models, each with its own LODs,
palettes, textures and shadows (``SceneRenderer(casts=...)``, ``piste view --rider-model``)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def course_scene():
    from piste.world.scene import Scene

    return Scene.default(0, objects=False)


def test_two_models_drawn_together(gl, gltf_model, course_scene):
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.riders import pack_for, rider_model
    from piste.world.scene import Scene

    s = course_scene
    m = rider_model(gltf_model("CesiumMan"))
    assert m.meshes[0].texture.shape[2] == 4
    cast = Scene(s.net, s.line, s.lights, model=m, pack=pack_for(m, 2, ahead=4.0, across=0.0), start=150.0)
    assert cast.lods[0].mesh.n_triangles != s.lods[0].mesh.n_triangles  # its own LODs
    assert cast.lods[0].palette.size != s.lods[0].palette.size or cast.model.skeleton.n_bones != s.model.skeleton.n_bones
    alone = SceneRenderer(s, size=(160, 112), ctx=gl, lightmap=None)
    both = SceneRenderer(s, size=(160, 112), ctx=gl, lightmap=None, casts=[cast])
    alone.terrain.resident_wait = both.terrain.resident_wait = True
    try:
        a = alone.render(0.5, count_rider_pixels=True)
        b = both.render(0.5, count_rider_pixels=True)
    finally:
        alone.release()
        both.release()
    assert a.stats["riders"] == 6 and b.stats["riders"] == 8 and b.stats["rider_models"] == 2
    extra = sum(lod_tris for lod_tris in (cast.lods[l].n_triangles for l in b.casts[0].rider_lod))
    assert b.stats["rider_triangles"] == a.stats["rider_triangles"] + extra
    assert b.stats["rider_pixels"] > a.stats["rider_pixels"] + 20  # the cast's riders are on screen
    assert len(b.stats["shadow_patches_per_rider"]) == 8 and min(b.stats["shadow_patches_per_rider"]) >= 1
    diff = np.abs(a.image[..., :3].astype(int) - b.image[..., :3].astype(int)).max(-1)
    assert (diff > 30).sum() > 20


def test_rider_model_merges_primitives(gltf_model):
    from piste.world.riders import merged_mesh, pack_for, rider_model

    g = gltf_model("Girl")
    mesh = merged_mesh(g)
    assert mesh.n_vertices == sum(x.n_vertices for x in g.meshes if x.skinned)
    m = rider_model(g)
    assert len(m.meshes) == 1
    pack = pack_for(m, 3)
    assert [p[0] for p in pack] == [sorted(m.clips)[i % len(m.clips)] for i in range(3)]
