"""Terrain frames: crack-freedom under mixed LOD, culling, LOD views and reference images."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from piste.errors import ConfigError
from piste.render import TerrainRenderer
from piste.terrain.tessellate import TerrainMesh, tessellate
from piste.world.camera import Camera

MAGENTA = (1.0, 0.0, 1.0, 1.0)
VIEWS = {
    # straight down, orthographic: the bent (wave) edges would open x-y gaps at T-junctions
    "above": dict(eye=[15, 15, 50], target=[15, 15, 0], up=(0, 1, 0), ortho_height=34, near=1, far=100),
    # low and oblique, perspective: height gaps would show
    "oblique": dict(eye=[15, -12, 14], target=[15, 14, 0], fov_y=70, near=0.5, far=200),
}


@pytest.fixture(scope="module")
def wavy(gl_context, grid_net):
    net = grid_net(3, 3, size=10.0, relief=3.0, wave=2.5)
    r = TerrainRenderer(net, size=(128, 128), ctx=gl_context)
    yield net, r
    r.release()


def _magenta(img):
    return (img[..., :3] == (255, 0, 255)).all(axis=-1)


def _merge(a: TerrainMesh, b: TerrainMesh) -> TerrainMesh:
    """Two meshes drawn as one (no glue between them: T-junctions crack)."""
    cat = lambda k: np.concatenate([getattr(a, k), getattr(b, k)])  # noqa: E731
    return TerrainMesh(
        positions=cat("positions"), normals=cat("normals"), uv=cat("uv"), uv_lightmap=cat("uv_lightmap"),
        uv_projected=cat("uv_projected"), param=cat("param"), indices=np.concatenate([a.indices, b.indices + len(a.positions)]),
        patch_ids=cat("patch_ids"), patch_kind=cat("patch_kind"), patch_levels=cat("patch_levels"),
        vertex_patch=np.concatenate([a.vertex_patch, b.vertex_patch + len(a.patch_ids)]),
        vertex_start=None, tri_start=None,
    )


@pytest.mark.parametrize("view", sorted(VIEWS))
def test_mixed_lod_has_no_cracks(gl, wavy, view):
    net, r = wavy
    cam = Camera(**VIEWS[view])
    kw = dict(sky=False, fog=0, clear=MAGENTA)
    full = r.render(cam, lod=False, **kw).image
    inside = ndimage.binary_erosion(~_magenta(full), iterations=2)  # the footprint, away from its outline
    assert inside.mean() > 0.2
    rng = np.random.default_rng(7)
    mixes = {
        "random per edge": rng.choice([4, 6, 8], net.n_edges),
        "by distance": net.edge_levels(np.array([0.0, 0.0, 5.0]), near=12.0, far=25.0),
    }
    for name, levels in mixes.items():
        frame = r.render(cam, levels=levels, **kw)
        assert frame.kind_counts[0] > 0, name  # glue patches present
        holes = _magenta(frame.image) & inside
        assert not holes.any(), f"{view}, {name}: {holes.sum()} background pixels show through the terrain"
    # the test can see cracks: patches tessellated alone at 4 and 8 without glue do crack
    ids = np.arange(len(net))
    cracked = _merge(tessellate(net, 4, patches=ids[ids % 2 == 0]), tessellate(net, 8, patches=ids[ids % 2 == 1]))
    frame = r.draw(cam, cracked, **kw)
    assert (_magenta(frame.image) & inside).sum() > 5


def test_lod_off_is_all_8x8_and_lod_on_mixes(gl, wavy):
    net, r = wavy
    cam = Camera([2.0, 2.0, 6.0], [20.0, 20.0, 0.0])
    off = r.render(cam, lod=False, read=False)
    assert off.kind_counts[8] == off.patches > 0 and off.triangles == 98 * off.patches
    r.lod_kwargs = dict(near=10.0, far=25.0)
    try:
        on = r.render(cam, read=False)
    finally:
        r.lod_kwargs = {}
    assert on.kind_counts[4] and on.kind_counts[0] and on.triangles < off.triangles
    assert set(on.timings) >= {"lod", "cull", "tessellate", "upload", "draw", "readback", "cpu", "gpu", "total"}


def test_culling_drops_only_invisible_patches(gl, grid_net):
    net = grid_net(6, 6, size=10.0)
    r = TerrainRenderer(net, size=(64, 48), ctx=gl)
    try:
        cam = Camera([30.0, -5.0, 6.0], [30.0, 10.0, 2.0], fov_y=40)
        frame = r.render(cam, lod=False)
        assert 0 < frame.patches < len(net)
        everything = r.draw(cam, tessellate(net, 8), fog=0)
        culled = r.render(cam, lod=False, fog=0)
        assert np.array_equal(everything.image, culled.image)
        away = r.render(Camera([30.0, -5.0, 6.0], [30.0, -30.0, 6.0]), lod=False)
        assert away.patches == 0 and away.triangles == 0
    finally:
        r.release()


def test_bad_modes_are_config_errors(gl, wavy):
    _, r = wavy
    cam = Camera(**VIEWS["oblique"])
    with pytest.raises(ConfigError, match="lightmap mode"):
        r.render(cam, lightmap_mode="multiply")
    with pytest.raises(ConfigError, match="debug view"):
        r.render(cam, debug="normals")


@pytest.mark.parametrize("name, kw", [
    ("hill_modulate", dict(lightmap_mode="modulate")),
    ("hill_ps2", dict(lightmap_mode="ps2")),
    ("hill_lod", dict(debug="lod")),
    ("hill_track_ps2", dict(lightmap_mode="ps2")),
])
def test_reference_images(gl, grid_net, reference_image, name, kw):
    net = grid_net(4, 4, size=10.0, relief=5.0)
    y = np.linspace(0.0, 40.0, 30)
    track = np.stack([20.0 + 4.0 * np.sin(y / 8.0), y, np.zeros_like(y)], axis=1) if "track" in name else None
    r = TerrainRenderer(net, size=(96, 64), ctx=gl, lod_near=14.0, lod_far=30.0, track=track, track_half_width=4.0)
    try:
        frame = r.render(Camera([4.0, -6.0, 12.0], [22.0, 22.0, 0.0], fov_y=60), **kw)
    finally:
        r.release()
    reference_image(name, frame.image)
