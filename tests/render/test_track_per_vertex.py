"""The groomed track's distance looked up per vertex (terrain.vert.glsl's ``v_track_d``, compiled with
``TERRAIN_TRACK 1``) instead of per pixel: the default course's frames hold against the per-pixel
look-up it replaced (kept below as the reference shader) within the reference pictures' tolerance,
on the resident (geomorphed) and the CPU path, in both light-map modes; and the track is drawn."""

from __future__ import annotations

import numpy as np
import pytest

from piste.render import TerrainRenderer
from piste.render.terrain_pass import _MODE_ID, _with_defines
from piste.world.camera import track_camera
from piste.world.course import TRACK_HALF_WIDTH, default_course, track_centerline


def _per_pixel(tp, ctx):
    """The modulate program with the track field looked up per pixel (the shader before)."""
    vs = tp._vs.replace("out float v_track_d;", "out float v_track_d;\nout vec2 v_trk;").replace(
        "    v_kind = in_kind;", "    v_kind = in_kind;\n    v_trk = (p.xy - u_track_rect.xy) * u_track_rect.zw;")
    fs = tp._fs.replace("in float v_track_d;", "in vec2 v_trk;\nuniform sampler2D u_track;").replace(
        "base_color(v_uv, v_track_d)", "base_color(v_uv, texture(u_track, v_trk).r)")
    assert vs != tp._vs and fs.count("texture(u_track, v_trk)") == 2  # (modulate and base modes)
    return ctx.program(vertex_shader=_with_defines(vs, TERRAIN_TRACK=1),
                       fragment_shader=_with_defines(fs, TERRAIN_MODE=0, TERRAIN_TRACK=1))


@pytest.fixture(scope="module")
def course():
    return default_course(), track_centerline()


@pytest.mark.parametrize("resident", [True, False])
def test_track_per_vertex_holds_against_the_per_pixel_lookup(gl, course, resident):
    net, line = course
    kw = dict(size=(320, 224), ctx=gl, track=line, track_half_width=TRACK_HALF_WIDTH)
    r = TerrainRenderer(net, resident=resident, **kw)
    bare = TerrainRenderer(net, size=(320, 224), ctx=gl, track=None, resident=resident)
    r.resident_wait = bare.resident_wait = True
    tp = r.terrain
    try:
        cams = [track_camera(line, t, aspect=320 / 224) for t in (0.15, 0.5, 0.8)]
        r.render(cams[0])  # the modulate program compiled
        key = tp._key(_MODE_ID["modulate"])
        now = tp._programs[key]
        assert "u_track" in now  # the vertex shader samples the field
        before = tp._apply(_per_pixel(tp, gl))
        for cam in cams:
            img = r.render(cam).image[..., :3].astype(int)
            tp._programs[key] = before
            try:
                ref = r.render(cam).image[..., :3].astype(int)
            finally:
                tp._programs[key] = now
            no_track = bare.render(cam).image[..., :3].astype(int)
            d = np.abs(img - ref)
            # the reference pictures' tolerance (mean < 2, < 0.5 % off by > 16) and much closer:
            # only pixels on the dye lines' edges move
            assert d.mean() < 0.05 and (d.max(-1) > 16).mean() < 0.001, (d.mean(), (d.max(-1) > 16).mean())
            # and the track is there: groomed snow and dye lines differ from the bare terrain
            assert (np.abs(img - no_track).max(-1) > 16).sum() > 200
        before.release()
    finally:
        r.release()
        bare.release()


def test_ps2_mode_draws_the_same_track(gl, course):
    """The PS2 second pass derives Cs from the same per-vertex distance: its frame stays within 2
    steps of modulate's (the talk's identity) with the track on."""
    net, line = course
    r = TerrainRenderer(net, size=(320, 224), ctx=gl, track=line, track_half_width=TRACK_HALF_WIDTH)
    r.resident_wait = True
    try:
        cam = track_camera(line, 0.4, aspect=320 / 224)
        mod = r.render(cam, fog=None, sky=False).image[..., :3].astype(int)
        ps2 = r.render(cam, fog=None, sky=False, lightmap_mode="ps2").image[..., :3].astype(int)
        assert (np.abs(mod - ps2).max(-1) > 2).mean() < 0.001
    finally:
        r.release()
