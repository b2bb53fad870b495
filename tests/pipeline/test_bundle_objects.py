"""A bundle as the scene's objects (piste.pipeline.bundle_objects): the net, light map, lights,
cameras and visibility built from the arrays that piste.formats.bundle reads."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bundle import camera_to_dict, write_bundle
from piste.pipeline import Bundle, load_bundle
from piste.pipeline.bundle_objects import camera_from_dict, lights_from_dict
from piste.terrain.net import PatchNet


def _minimal(tmp_path, control_points=None):
    g = np.zeros((7, 7, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(7.0))
    g[..., 2] = 0.1 * g[..., 0]
    net = PatchNet.from_control_grid(g)
    arrays = {
        "terrain/control_points": net.control_points if control_points is None else control_points,
        "terrain/uv": net.uv,
        "lightmap/atlas": np.full((20, 20, 3), 0.5, np.float32),
        "lightmap/rects": net.lightmap_rect,
    }
    man = {"name": "mini", "terrain": {"name": "mini", "tol": net.tol},
           "lights": {"ambient": [{"color": [1.0, 1.0, 1.0], "intensity": 0.5, "name": ""}],
                      "point": [{"position": [0.0, 0.0, 1.0], "color": [1.0, 1.0, 1.0], "intensity": 1.0, "range": "inf",
                                 "falloff": 1.0, "shadows": True, "name": "p"}]},
           "cameras": [{"name": "c", "eye": [0.0, -5.0, 5.0], "target": [3.0, 3.0, 0.0], "up": [0.0, 0.0, 1.0],
                        "fov_y": 50.0, "near": 0.1, "far": 100.0, "ortho_height": None}],
           "lightmap": {"res": 8, "gutter": 1}}
    return write_bundle(tmp_path / "b.piste", man, arrays), arrays


def test_objects_built_from_the_arrays(tmp_path):
    path, arrays = _minimal(tmp_path)
    b = load_bundle(path)
    assert isinstance(b, Bundle) and b.name == "mini"
    assert len(b.net) == 4 and np.array_equal(b.net.control_points, arrays["terrain/control_points"])
    assert b.lightmap.atlas.shape == (20, 20, 3) and b.lightmap.atlas.dtype == np.float32
    assert len(b.lights) == 2 and np.isinf(b.lights.direct[0].range)
    assert b.camera("c").fov_y == 50.0 and b.camera().near == 0.1
    assert b.objects() is None and b.rider_model() is None and b.visibility is None and b.centerline is None


def test_camera_and_lights_round_trip(tmp_path):
    path, _ = _minimal(tmp_path)
    b = load_bundle(path)
    cam = b.camera("c")
    again = camera_from_dict(camera_to_dict(cam))
    assert np.allclose(again.eye, cam.eye) and again.far == cam.far and again.ortho_height is None
    lights = lights_from_dict(b.manifest["lights"])
    assert [type(x).__name__ for x in lights] == [type(x).__name__ for x in b.lights]


def test_bad_terrain_names_the_member(tmp_path):
    path, _ = _minimal(tmp_path, control_points=np.zeros((4, 3, 3, 3)))
    with pytest.raises(FormatError) as e:
        load_bundle(path)
    assert e.value.field == "terrain/control_points.npy" and "invalid terrain" in str(e.value)


def test_warm_load_starts_the_resident_blocks(tmp_path):
    """load_bundle(warm=True) (piste demo / render / view) starts the terrain's resident vertex
    blocks in the background as soon as the net exists; a plain load starts nothing."""
    from piste.terrain.resident import resident_terrain

    path, _ = _minimal(tmp_path)
    cold = load_bundle(path)
    assert not cold.net.__dict__.get("_resident_pending") and not cold.net.__dict__.get("_resident")
    warm = load_bundle(path, warm=True)
    jobs = warm.net.__dict__.get("_resident_pending") or {}
    assert len(jobs) == 1
    next(iter(jobs.values()))["thread"].join(30)
    r = resident_terrain(warm.net, wait=False)  # built: returned at once, not started again
    assert r is not None and r.vertices.shape == (len(warm.net) * r.block, 11)


def test_the_light_map_atlas_is_the_stored_member_not_a_copy(tmp_path):
    """The light map's atlas is the bundle's float32 member as read (a read-only view of the mapped
    file, no copy a start); the net's control points are its own writable copy."""
    path, arrays = _minimal(tmp_path)
    b = load_bundle(path)
    assert b.lightmap.atlas is b.arrays["lightmap/atlas"] or np.shares_memory(b.lightmap.atlas, b.arrays["lightmap/atlas"])
    assert np.array_equal(b.lightmap.atlas, arrays["lightmap/atlas"]) and not b.lightmap.atlas.flags.writeable
    assert b.net.control_points.flags.writeable and not np.shares_memory(b.net.control_points,
                                                                         b.arrays["terrain/control_points"])


def _furnished(tmp_path, drop=(), change=None):
    """The minimal bundle with 20 course objects placed (furnish.add_objects: their level chains stored
    beside the meshes, as a build stores them), written and loaded again; ``drop``: member names left
    out, ``change``: ``{member: array}`` written instead."""
    from piste.pipeline.furnish import add_objects

    path, _ = _minimal(tmp_path)
    big = load_bundle(path).net.control_points * np.array([40.0, 40.0, 1.0])  # 240 m square: room for them
    path, _ = _minimal(tmp_path, control_points=big)
    b = add_objects(load_bundle(path), 20)
    arrays = {k: v for k, v in b.arrays.items() if k not in drop}
    arrays.update(change or {})
    man = {k: v for k, v in b.manifest.items() if k not in ("format", "members")}
    return load_bundle(write_bundle(tmp_path / "furnished.piste", man, arrays))


def test_object_level_chains_are_read_from_the_bundle_as_computed(tmp_path):
    from piste.world.object_lod import object_lods

    objs = _furnished(tmp_path).objects()
    assert objs is not None and set(objs.meshes) >= {"tree", "rock"}
    for m in objs.meshes.values():
        want = object_lods(m.decode()[0], m.indices)
        assert m.lods is not None and len(m.lods) == len(want)
        for got, ref in zip(m.lods, want):
            assert np.array_equal(got.indices, ref.indices) and got.error == ref.error
    assert any(len(m.lods) > 1 for m in objs.meshes.values())


def test_a_bundle_without_object_level_chains_leaves_them_to_the_renderer(tmp_path):
    kinds = ("tree", "rock", "sign", "rail")
    objs = _furnished(tmp_path, drop={f"objects/meshes/{k}/lod_errors" for k in kinds}).objects()
    assert all(m.lods is None for m in objs.meshes.values())


def test_bad_object_level_chains_name_the_member(tmp_path):
    b = _furnished(tmp_path)
    tris = b.arrays["objects/meshes/tree/lod_triangles"]
    with pytest.raises(FormatError) as e:
        _furnished(tmp_path, change={"objects/meshes/tree/lod_triangles": tris[::-1].copy()}).objects()
    assert "objects/meshes/tree/lod_triangles.npy" in str(e.value) and "strictly fewer" in str(e.value)
    idx = b.arrays["objects/meshes/tree/lod_indices"].copy()
    idx[-1] = 1 << 20
    with pytest.raises(FormatError) as e:
        _furnished(tmp_path, change={"objects/meshes/tree/lod_indices": idx}).objects()
    assert "objects/meshes/tree/lod_indices.npy" in str(e.value) and "past the mesh" in str(e.value)


def _with_track(tmp_path, texel=None, field=None):
    """The minimal bundle with a centre line and the track texture the build stores for it."""
    from piste.render.textures import TRACK_TEXEL, track_field, track_texels

    path, arrays = _minimal(tmp_path)
    b = load_bundle(path)
    line = np.array([[3.0, 6.0, 0.0], [2.5, 3.0, 0.0], [3.0, 0.0, 0.0]])
    f, rect = track_field(line, b.net.bounds)
    arrays = dict(arrays, **{"terrain/centerline": line, "terrain/track_field": track_texels(f) if field is None else field,
                             "terrain/track_rect": rect})
    man = {k: v for k, v in b.manifest.items() if k not in ("format", "members")}
    man["terrain"] = dict(man["terrain"], track_texel=TRACK_TEXEL if texel is None else texel)
    return load_bundle(write_bundle(tmp_path / "track.piste", man, arrays)), f, rect


def test_the_stored_track_texture_is_what_the_renderer_would_upload(tmp_path):
    from piste.render.textures import track_texels

    b, f, rect = _with_track(tmp_path)
    field, r = b.track_texture()
    assert field.dtype == np.float16 and np.array_equal(field, track_texels(f)) and np.array_equal(r, rect)
    assert track_texels(field) is field  # the terrain pass uploads it as it is


def test_a_track_texture_of_another_spacing_is_recomputed_and_a_bad_one_names_the_member(tmp_path):
    b, _, _ = _with_track(tmp_path, texel=0.5)
    assert b.track_texture() is None
    b, f, _ = _with_track(tmp_path, field=np.zeros((3, 3), np.float16))
    with pytest.raises(FormatError) as e:
        b.track_texture()
    assert "terrain/track_field.npy" in str(e.value) and "float16" in str(e.value)


def test_a_preview_draws_the_stored_track_texture_without_computing_it(tmp_path, gl, monkeypatch):
    import piste.render.frame as frame
    from piste.pipeline.preview import ScenePreview

    b, _, _ = _with_track(tmp_path)
    p = ScenePreview(b, size=(64, 48), ctx=gl)
    try:
        want = p.render(b.camera("c"))
    finally:
        p.release()

    def refuse(*a, **k):
        raise AssertionError("track_field computed at set-up although the bundle stores it")

    monkeypatch.setattr(frame, "track_field", refuse)
    p = ScenePreview(b, size=(64, 48), ctx=gl)
    try:
        assert np.array_equal(p.render(b.camera("c")), want)
        assert p.terrain.terrain.track is not None
    finally:
        p.release()


def _with_texels(tmp_path, texels=None, name="texels.piste"):
    """The minimal bundle with a varied atlas (over-bright, -0.0, 0) and the float16 texels the build
    stores for it (``texels``: stored instead; ``False``: none, as an older bundle)."""
    from piste.render.textures import light_texels

    path, arrays = _minimal(tmp_path)
    b = load_bundle(path)
    atlas = np.random.default_rng(3).uniform(0.0, 2.5, (20, 20, 3)).astype(np.float32)
    atlas[0, 0], atlas[1, 1] = -0.0, 0.0
    arrays = dict(arrays, **{"lightmap/atlas": atlas})
    if texels is not False:
        arrays["lightmap/texels"] = light_texels(atlas) if texels is None else texels
    man = {k: v for k, v in b.manifest.items() if k not in ("format", "members")}
    return load_bundle(write_bundle(tmp_path / name, man, arrays)), atlas


def test_the_stored_light_map_texels_are_what_the_renderer_would_upload(tmp_path):
    from piste.render.textures import light_texels

    b, atlas = _with_texels(tmp_path)
    t = b.lightmap_texels()
    assert t is b.arrays["lightmap/texels"] and t.dtype == np.float16 and t.shape == (20, 20, 3)
    assert np.array_equal(t.view(np.uint16), light_texels(atlas).view(np.uint16))  # bit for bit (-0.0 kept)
    assert light_texels(t) is t  # the terrain pass uploads it as it is
    old, _ = _with_texels(tmp_path, texels=False, name="old.piste")
    assert old.lightmap_texels() is old.lightmap.atlas  # an older bundle: the atlas, converted at upload
    b.lightmap.atlas = np.zeros((20, 20, 3), np.float32)  # replaced after loading: the new atlas, not stale texels
    assert b.lightmap_texels() is b.lightmap.atlas


@pytest.mark.parametrize("texels, says", [(np.zeros((20, 20, 3), np.float32), "float16"),
                                          (np.zeros((20, 19, 3), np.float16), "(20, 20, 3)"),
                                          (np.full((20, 20, 3), np.inf, np.float16), "finite"),
                                          (np.full((20, 20, 3), -1.0, np.float16), "negative")])
def test_bad_light_map_texels_name_the_member(tmp_path, texels, says):
    b, _ = _with_texels(tmp_path, texels=texels)
    with pytest.raises(FormatError) as e:
        b.lightmap_texels()
    assert "lightmap/texels.npy" in str(e.value) and says in str(e.value)


def test_a_preview_draws_the_stored_light_map_texels_as_it_draws_the_atlas(tmp_path, gl, monkeypatch):
    import piste.render.terrain_pass as terrain_pass
    from piste.pipeline.preview import ScenePreview

    convert = terrain_pass.light_texels

    def only_stored(a):
        assert a.dtype == np.float16, "the float32 atlas converted at set-up although the bundle stores its texels"
        return convert(a)

    images = []
    for texels, name in ((False, "old.piste"), (None, "new.piste")):
        b, _ = _with_texels(tmp_path, texels=texels, name=name)
        p = ScenePreview(b, size=(64, 48), ctx=gl)
        try:
            images.append(p.render(b.camera("c")))
        finally:
            p.release()
        monkeypatch.setattr(terrain_pass, "light_texels", only_stored)  # (for the bundle with texels)
    assert np.array_equal(images[0], images[1])
