"""The GPU-resident terrain path: with geomorphing off it draws exactly the CPU path's pictures;
with it on, crossing a LOD threshold no longer pops."""

from __future__ import annotations

import numpy as np
import pytest

from piste.render import TerrainRenderer
from piste.terrain.resident import ResidentMesh
from piste.terrain.tessellate import TerrainMesh
from piste.world.camera import Camera


@pytest.mark.parametrize("kw", [dict(lightmap_mode="modulate"), dict(lightmap_mode="ps2"), dict(debug="lod"),
                                dict(debug="wire")])
def test_resident_without_morph_draws_the_cpu_paths_picture(gl, grid_net, kw):
    net = grid_net(4, 4, size=10.0, relief=5.0)
    y = np.linspace(0.0, 40.0, 30)
    track = np.stack([20.0 + 4.0 * np.sin(y / 8.0), y, np.zeros_like(y)], axis=1)
    cam = Camera([4.0, -6.0, 12.0], [22.0, 22.0, 0.0], fov_y=60)
    images = {}
    for resident in (False, True):
        r = TerrainRenderer(net, size=(96, 64), ctx=gl, lod_near=14.0, lod_far=30.0, track=track,
                            track_half_width=4.0, lod_morph=False, resident=resident)
        r.resident_wait = True  # the resident path from the first frame (not the CPU path while it builds)
        try:
            frame = r.render(cam, **kw)
            assert isinstance(r.mesh, ResidentMesh if resident else TerrainMesh)
            assert frame.kind_counts[0] > 0 and frame.kind_counts[4] > 0  # a real LOD mix
            images[resident] = (frame.image, frame.triangles, frame.kind_counts)
        finally:
            r.release()
    assert images[True][1:] == images[False][1:]
    diff = np.abs(images[True][0].astype(int) - images[False][0].astype(int))
    assert (diff > 0).mean() < 1e-3, f"{(diff > 0).sum()} pixels differ"


def test_first_frames_do_not_wait_for_the_vertex_blocks(gl, grid_net):
    """A fresh renderer draws at once on the CPU path (visible patches only) while the resident
    blocks build in the background; then it switches, with the same picture (morph off)."""
    import time

    net = grid_net(4, 4, size=10.0, relief=5.0)
    cam = Camera([4.0, -6.0, 12.0], [22.0, 22.0, 0.0], fov_y=60)
    r = TerrainRenderer(net, size=(96, 64), ctx=gl, lod_near=14.0, lod_far=30.0, lod_morph=False)
    r.resident_wait = False  # the interactive setting (the default waits: timing-independent pictures)
    try:
        first = r.render(cam)
        assert isinstance(r.mesh, TerrainMesh)
        deadline = time.time() + 60
        while not isinstance(r.mesh, ResidentMesh):
            assert time.time() < deadline, "the resident blocks never arrived"
            time.sleep(0.05)
            later = r.render(cam)
        assert later.triangles == first.triangles
        diff = np.abs(later.image.astype(int) - first.image.astype(int))
        assert diff.mean() < 0.05 and diff.max() <= 8
    finally:
        r.release()


def test_geomorph_factors_reach_the_gpu(gl, grid_net):
    """Factor 1 everywhere draws the unmorphed picture exactly; factor 0 puts every fine vertex on
    the coarser level's shape (the picture changes); the live factors sit in between."""
    net = grid_net(3, 3, size=10.0, relief=6.0, wave=2.5)
    checker = np.kron((np.indices((16, 16)).sum(0) % 2 * 255).astype(np.uint8), np.ones((8, 8), np.uint8))
    checker = np.repeat(checker[..., None], 3, axis=2)  # a sharp pattern: any shift of the surface shows
    cam = Camera([-3.0, -3.0, 8.0], [15.0, 15.0, 0.0], fov_y=60)
    kw = dict(fog=0, sky=False)
    r = TerrainRenderer(net, size=(160, 120), ctx=gl, lod_near=12.0, lod_far=25.0, lightmap=None,
                        base_texture=checker, lod_morph=True)
    r.resident_wait = True
    try:
        mesh = r.prepare(cam)
        assert mesh.morph and 0.0 < mesh.factors[:net.n_edges].min() < 1.0  # some edges inside a morph band
        live = r.draw(cam, mesh, **kw).image
        mesh.factors[:] = 1.0
        one = r.draw(cam, mesh, **kw).image
        mesh.factors[:] = 0.0
        zero = r.draw(cam, mesh, **kw).image
        mesh.morph = False
        off = r.draw(cam, mesh, **kw).image
    finally:
        r.release()
    assert np.array_equal(one, off)
    changed = lambda a, b: int((np.abs(a.astype(int) - b).max(-1) > 64).sum())  # noqa: E731
    assert changed(zero, off) > 50
    assert changed(live, off) < changed(zero, off)
