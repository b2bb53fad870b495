"""piste build: steps cached by content hash, byte-identical bundles, only changed steps rebuilt."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.cache import Cache, Hasher, content_key


def test_rebuild_reuses_every_step_and_is_byte_identical(small_scene):
    scene = small_scene()
    r1 = build_scene(scene)
    a = r1.path.read_bytes()
    assert set(r1.rebuilt) >= {"terrain", "lightmap", "characters", "objects", "visibility"}
    r2 = build_scene(scene)
    assert set(r2.cached) == {"terrain", "lod_errors", "lightmap", "shadow", "characters", "objects", "visibility", "object_visibility"}
    assert r2.path.read_bytes() == a
    # no cache at all: the same bytes again
    r3 = build_scene(scene, out=scene.with_name("nocache.piste"), use_cache=False)
    assert r3.path.read_bytes() == a
    assert not list(scene.parent.glob(".*.tmp"))  # atomic write left nothing behind


def test_changing_a_light_rebuilds_only_what_depends_on_it(small_scene):
    scene = small_scene()
    build_scene(scene)
    before = load_bundle(scene.with_suffix(".piste"))
    scene.write_text(scene.read_text().replace("intensity = 1.0", "intensity = 0.5"))
    r = build_scene(scene)
    assert set(r.rebuilt) == {"lightmap", "objects", "write"}
    assert set(r.cached) == {"terrain", "lod_errors", "shadow", "characters", "visibility", "object_visibility"}
    after = load_bundle(r.path)
    assert after.arrays["lightmap/atlas"].mean() < before.arrays["lightmap/atlas"].mean()
    # and back: every step from the cache, the first bundle's bytes
    scene.write_text(scene.read_text().replace("intensity = 0.5", "intensity = 1.0"))
    r = build_scene(scene)
    assert set(r.cached) == {"terrain", "lod_errors", "lightmap", "shadow", "characters", "objects", "visibility", "object_visibility"}



def test_terrain_file_change_rebuilds_terrain_lightmap_objects_visibility(small_scene):
    scene = small_scene()
    build_scene(scene)
    data = dict(np.load(scene.parent / "hill.npz"))
    data["z"] = data["z"] + 1.0
    np.savez(scene.parent / "hill.npz", **data)
    r = build_scene(scene)
    assert {"terrain", "lightmap", "objects", "visibility"} <= set(r.rebuilt)
    assert "characters" in r.cached


def test_corrupt_cache_entry_is_recomputed(small_scene):
    scene = small_scene(riders=False)
    build_scene(scene)
    entries = list((scene.parent / ".piste-cache" / "lightmap").glob("*.npz"))
    assert entries
    entries[0].write_bytes(b"not a zip")
    r = build_scene(scene)
    assert "lightmap" in r.rebuilt
    assert load_bundle(r.path).lightmap.atlas.shape[2] == 3


def test_bundle_is_a_sorted_zip_with_fixed_times(small_scene):
    r = build_scene(small_scene())
    with zipfile.ZipFile(r.path) as zf:
        names = zf.namelist()
        assert names[0] == "manifest.json"
        assert names[1:] == sorted(names[1:])
        assert all(i.date_time == (1980, 1, 1, 0, 0, 0) for i in zf.infolist())


def test_unknown_clip_is_a_config_error(small_scene):
    scene = small_scene(riders=False, extra='\n[[riders]]\nposition = [60.0, 60.0]\nclip = "moonwalk"\n')
    with pytest.raises(ConfigError, match="moonwalk"):
        build_scene(scene)


def test_rider_off_the_terrain_is_a_config_error(small_scene):
    scene = small_scene(riders=False, extra="\n[[riders]]\nposition = [900.0, 60.0]\n")
    with pytest.raises(ConfigError, match="off the terrain"):
        build_scene(scene)


def test_hasher_parts_are_typed_and_cache_round_trips(tmp_path):
    assert content_key("ab") != content_key("a", "b")
    assert content_key(np.zeros(3)) != content_key(np.zeros(3, np.float32))
    assert Hasher(1, [2.0]).hexdigest() == Hasher(1, [2.0]).hexdigest()
    c = Cache(tmp_path)
    assert c.get("step", "k") is None
    c.put("step", "k", {"a": np.arange(4)}, {"x": 1})
    arrays, meta = c.get("step", "k")
    assert meta == {"x": 1} and arrays["a"].tolist() == [0, 1, 2, 3]
    assert Cache(None).get("step", "k") is None


def test_moving_an_object_retests_only_the_objects(small_scene):
    scene = small_scene(riders=False)
    build_scene(scene)
    scene.write_text(scene.read_text().replace("position = [70.0, 70.0]", "position = [72.0, 71.0]"))
    r = build_scene(scene)
    assert set(r.rebuilt) == {"objects", "object_visibility", "write"}
    b = load_bundle(r.path)
    assert b.visibility.n_objects == 2 and b.visibility.objects_at((60.0, 60.0, 40.0)).shape == (2,)
