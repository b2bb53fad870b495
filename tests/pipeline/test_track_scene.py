"""Scene-file keys the runtime carries out: ``[pack] follow = "track"`` (riders running down the
default course), ``[auto_objects]`` (the course's placed objects), ``[render] fog`` and
``[render] face`` -- parsed (world.scene_file), carried by ``piste build`` into the manifest, made
and used by :class:`piste.pipeline.preview.ScenePreview`."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.preview import ScenePreview, auto_objects, camera_at
from piste.world.objects import place_objects
from piste.world.scene_file import AutoObjectsSpec, PackSpec, loads_scene

SCENE = """\
name = "pack"
[terrain]
source = "default"
[lightmap]
res = 2
shadows = false
[visibility]
enabled = false
[render]
fog = {fog}
face = "{face}"
object_lod = 2.0
[pack]
follow = "track"
start = 0.2
[auto_objects]
seed = 3
trees = 12
signs = 2
rocks = 3
rails = 1
[[cameras]]
name = "fly"
track = [0.2, 0.3]
"""


def _build(tmp_path, fog="0.004", face="null_bones"):
    p = tmp_path / "pack.toml"
    p.write_text(SCENE.format(fog=fog, face=face))
    return load_bundle(build_scene(p).path)


def test_keys_parse_with_defaults_and_errors(tmp_path):
    s = loads_scene(SCENE.format(fog='"auto"', face="morph"), tmp_path / "a.toml")
    assert s.pack == PackSpec("track", 0.2) and s.pack.as_dict() == {"follow": "track", "start": 0.2}
    assert s.auto_objects == AutoObjectsSpec(seed=3, trees=12, signs=2, rocks=3, rails=1)
    assert s.auto_objects.as_dict() == {"seed": 3, "trees": 12, "signs": 2, "rocks": 3, "rails": 1}
    assert s.render.fog == "auto" and s.render.face == "morph" and s.render.object_lod == 2.0
    assert loads_scene("", tmp_path / "e.toml").render.object_lod == 1.0  # (object_lod.DEFAULT_LOD_PIXELS)
    d = loads_scene("[pack]\n[auto_objects]\n", tmp_path / "b.toml")
    assert d.pack == PackSpec() and d.pack.as_dict() == {"follow": "track", "start": 0.12}
    assert d.auto_objects == AutoObjectsSpec()
    assert d.auto_objects.as_dict() == {"seed": 0, "trees": 220, "signs": 16, "rocks": 40, "rails": 6}
    assert loads_scene("", tmp_path / "c.toml").pack is None
    bad = [("[pack]\nfollow = 'rails'\n", "pack.follow"), ("[pack]\nstart = 1.5\n", "pack.start"),
           ("[auto_objects]\ntrees = -1\n", "auto_objects.trees"), ("[auto_objects]\nwho = 1\n", "who"),
           ("[render]\nfog = -0.1\n", "render.fog"), ("[render]\nfog = 'thick'\n", "render.fog"),
           ("[render]\nface = 'smile'\n", "render.face"), ("[render]\nobject_lod = -1\n", "render.object_lod"),
           ("[pack]\n[[riders]]\nposition = [1.0, 2.0]\n", "pack"),
           ("[auto_objects]\n[[objects]]\nmodel = 'builtin:tree'\nposition = [1.0, 2.0]\n", "auto_objects")]
    for text, key in bad:
        with pytest.raises(ConfigError, match=key.split(".")[-1]):
            loads_scene(text, tmp_path / "d.toml")


def test_pack_objects_fog_and_face_reach_the_runtime(tmp_path, gl):
    b = _build(tmp_path)
    assert b.manifest["pack"] == {"follow": "track", "start": 0.2}
    assert b.manifest["render"]["fog"] == 0.004 and b.manifest["render"]["face"] == "null_bones"
    objs = auto_objects(b)  # the course's placement of the scene file's seed and counts
    ref = place_objects(b.net, b.centerline, b.lights, seed=3, n_trees=12, n_signs=2, n_rocks=3, n_rails=1,
                        track_half_width=16.0)
    assert len(objs) == len(ref) == 18 and np.array_equal(objs.matrix, ref.matrix)
    p = ScenePreview(b, size=(64, 48), ctx=gl)
    try:
        assert p.follow and len(p.scene.riders) == 6 and p.renderer.face == "null_bones" and p.fog == 0.004
        assert len(p.scene.objects) == 18
        assert b.manifest["render"]["object_lod"] == 2.0 and p.renderer.objects.lod_pixels == 2.0
        foggy = p.render(None, 0.0)  # the chase camera behind rider 0
        p.release()
        p = ScenePreview(b, size=(64, 48), ctx=gl, fog=0.0, face="off", object_lod=0.0)
        assert p.renderer.face is None and p.fog == 0.0 and p.renderer.objects.lod_pixels == 0.0
        clear = p.render(None, 0.0)
        assert np.abs(foggy.astype(int) - clear.astype(int)).max() > 8  # the scene file's fog is drawn
        p.release()
        p = ScenePreview(b, size=(64, 48), ctx=gl, terrain_only=True)
        assert not p.follow and p.objects is None and p.renderer is None
        foggy = p.render(camera_at(b, "fly"))  # the scene file's fog on the terrain alone too
        assert foggy.std() > 1
        p.release()
        p = ScenePreview(b, size=(64, 48), ctx=gl, terrain_only=True, fog=0.0)
        assert np.abs(foggy.astype(int) - p.render(camera_at(b, "fly")).astype(int)).max() > 8
        with pytest.raises(ConfigError, match="120 m of track"):
            ScenePreview(b, size=(64, 48), ctx=gl, start=1.0)
    finally:
        p.release()
