"""Global illumination in the light-map bake (issue 27 item 4): ``bounces`` against piste's own
Monte Carlo path-traced reference on the valley scene (a sunlit wall facing a shaded one)."""

from __future__ import annotations

import numpy as np
import pytest
from lighting_nets import hill_net

from piste.cli import main
from piste.errors import ValidationError
from piste.lighting import AmbientLight, DirectionalLight, Lights, bake_lightmap, sample_points, shade
from piste.lighting.baker import BAKE_VERSION, load_lightmap
from piste.lighting.gi import (GatherHits, bounce_light, cosine_directions, off_fold, path_traced_reference, reference_error,
                               tile_lookup, valley_scene)
from piste.lighting.lightmap import inputs_key
from piste.terrain import PatchNet
from piste.world.scene_file import SceneError, loads_scene

RES = 8


@pytest.fixture(scope="module")
def valley():
    net, lights = valley_scene()
    pos, nrm = sample_points(net, RES)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    rng = np.random.default_rng(7)
    pick = np.sort(rng.choice(np.flatnonzero(off_fold(net, RES)), 128, replace=False))
    return net, lights, pos, nrm, pick


def test_two_bounces_within_3_percent_of_the_path_traced_reference(valley):
    net, lights, pos, nrm, pick = valley
    ref = path_traced_reference(net, lights, pos[pick], nrm[pick], bounces=2, paths=2048, seed=3)
    lm = bake_lightmap(net, lights, res=RES, bounces=2)
    err = reference_error(lm.tiles().reshape(-1, 3)[pick], ref)
    assert err.mean() <= 0.03, f"mean relative error {err.mean():.2%}"
    # the metric can fail: today's direct light (ambient everywhere, no inter-reflection) is far off
    direct = bake_lightmap(net, lights, res=RES)
    assert reference_error(direct.tiles().reshape(-1, 3)[pick], ref).mean() > 0.15
    # and so is one bounce short of the reference's two, on the shaded wall (patches 12-17)
    one = bake_lightmap(net, lights, res=RES, bounces=1)
    shaded = pick[pick // (RES * RES) >= 12]
    sel = np.isin(pick, shaded)
    e1 = reference_error(one.tiles().reshape(-1, 3)[shaded], ref[sel]).mean()
    e2 = err[sel].mean()
    assert e2 < e1


def test_shaded_wall_gets_the_sunlit_wall_s_light(valley):
    net, lights, *_ = valley
    luma = np.array([0.2126, 0.7152, 0.0722])
    t0 = bake_lightmap(net, lights, res=RES).tiles() @ luma
    t2 = bake_lightmap(net, lights, res=RES, bounces=2).tiles() @ luma
    shaded0, shaded2 = np.median(t0[12:18]), np.median(t2[12:18])  # (the median: the foot is welded to the floor)
    assert shaded0 == pytest.approx(lights.ambient_color() @ luma, rel=1e-6)  # ambient only today
    assert shaded2 > 1.4 * shaded0  # the sunlit wall and floor light it
    # the sunlit wall in direct sun changes little: the sky it loses is half its ambient, bounce adds
    assert abs(t2[6:12].mean() - t0[6:12].mean()) < 0.1 * t0[6:12].mean()


def test_an_open_plane_gets_exactly_the_sky_and_the_sun():
    """Nothing occludes a flat plane: every gather ray escapes, so the sky is the ambient light and
    any number of bounces gives today's light."""
    g = np.linspace(0.0, 30.0, 7)
    y, x = np.meshgrid(g, g, indexing="ij")
    net = PatchNet.from_control_grid(np.stack([x, y, np.zeros_like(x)], -1))
    lights = Lights((AmbientLight((0.4, 0.5, 0.7), 0.5), DirectionalLight((0.3, 0.2, -0.9), (1, 0.9, 0.8), 1.2)))
    plain = bake_lightmap(net, lights, res=RES)
    gi = bake_lightmap(net, lights, res=RES, bounces=3, gather_rays=16)
    assert gi.stats["gather_escaped"] == gi.stats["gather_rays"] == len(net) * RES * RES * 16
    np.testing.assert_allclose(gi.atlas, plain.atlas, rtol=1e-6, atol=1e-7)


def test_default_bake_keeps_its_key_and_manifest():
    net = hill_net()
    lights = Lights((AmbientLight((0.3, 0.3, 0.3), 1.0), DirectionalLight((0.4, 0.3, -0.8))))
    lm = bake_lightmap(net, lights, res=RES, bounces=0, sun_radius=0.0)
    assert lm.manifest["key"] == inputs_key(net, lights, RES, 1, True, 64, BAKE_VERSION)
    assert "gi" not in lm.manifest and "gather_rays" not in lm.stats
    pos, nrm = sample_points(net, RES)
    # bounces=0 is the lighting equation with hard shadows (here: the hill shadows nothing at the seams)
    unshadowed = bake_lightmap(net, lights, res=RES, shadows=False)
    direct = shade(lights, pos.reshape(-1, 3), nrm.reshape(-1, 3))
    assert np.abs(unshadowed.tiles().reshape(-1, 3) - direct).max() < 0.05  # welded seams only
    gi = bake_lightmap(net, lights, res=RES, bounces=1, gather_rays=4)
    assert gi.manifest["key"] != lm.manifest["key"] and gi.manifest["gi"]["bounces"] == 1


def test_bounce_bake_is_deterministic_whatever_the_chunks(tmp_path, valley):
    net, lights, *_ = valley
    a = bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16, sun_radius=1.0, sun_rays=4, chunk_size=64)
    b = bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16, sun_radius=1.0, sun_rays=4, chunk_size=5)
    assert np.array_equal(a.atlas, b.atlas)
    c = bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16, sun_radius=1.0, sun_rays=4, seed=1)
    assert not np.array_equal(a.atlas, c.atlas)

    # a bake stopped half-way resumes from its (wider) chunks to the same light
    class Stop(Exception):
        pass

    def stop(c_, done, total):
        if done == 2:
            raise Stop

    part = tmp_path / "partial"
    with pytest.raises(Stop):
        bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16, chunk_size=5, partial_dir=part, on_chunk=stop)
    r = bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16, chunk_size=5, partial_dir=part)
    assert r.resumed_chunks == 2
    assert np.array_equal(r.atlas, bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16).atlas)


def test_gather_helpers():
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, 0.0, 0.8]])
    d = cosine_directions(n, np.arange(3), 64, seed=0)
    assert d.shape == (3, 64, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    cos = np.einsum("krc,kc->kr", d, n)
    assert (cos > 0).all()
    assert abs(cos.mean() - 2.0 / 3.0) < 0.02  # E[cos] of the cosine-weighted hemisphere = 2/3
    assert np.array_equal(cosine_directions(n[1:], np.arange(1, 3), 64), d[1:])  # per-sample, batch-free
    tiles = np.arange(2 * 3 * 3 * 1, dtype=np.float64).reshape(2, 3, 3, 1)
    got = tile_lookup(tiles, np.array([1, 1, -1]), np.array([0.5, 1.0, 0.5]), np.array([0.5, 0.0, 0.5]))
    assert got[:, 0].tolist() == [9 + 4, 9 + 2, 0.0]
    # a sample whose rays all hit a tile of constant light 1: L = D + rho (bounce after bounce)
    hits = GatherHits(np.zeros((1, 4), np.int32), np.full((1, 4), 0.5, np.float32), np.full((1, 4), 0.5, np.float32))
    one = bounce_light(np.ones((1, 1, 1, 3)) * 0.5, hits, np.zeros(3), 3, albedo=0.5)
    np.testing.assert_allclose(one, 0.5 + 0.5 * (0.5 + 0.5 * (0.5 + 0.5 * 0.5)))


@pytest.mark.parametrize("kw", [dict(bounces=-1), dict(bounces=17), dict(bounces=1.5), dict(bounces=True),
                                dict(bounces=1, gather_rays=10), dict(bounces=1, albedo=1.5),
                                dict(sun_radius=float("nan")), dict(sun_radius=-1), dict(sun_radius=20),
                                dict(sun_radius=1, sun_rays=3), dict(bounces=1, tracer="optix")])
def test_bad_settings_are_refused(kw):
    net = hill_net(1, 1)
    with pytest.raises(ValidationError):
        bake_lightmap(net, Lights((DirectionalLight(),)), res=RES, **kw)


def test_cli_and_scene_keys(tmp_path, capsys):
    net, lights = valley_scene()
    net.save(tmp_path / "valley.npz")
    from piste.lighting import dumps_lights

    (tmp_path / "l.toml").write_text(dumps_lights(lights))
    out = tmp_path / "lm"
    args = ["bake", str(tmp_path / "valley.npz"), "--lights", str(tmp_path / "l.toml"), "--out", str(out),
            "--jobs", "1", "--quiet", "--bounces", "1", "--sun-radius", "0.27"]
    assert main(args) == 0
    said = capsys.readouterr().out
    assert "1 bounces (" in said and "sun radius 0.27 deg (up to 64 rays per sample)" in said
    lm = load_lightmap(out)
    assert lm.manifest["gi"]["bounces"] == 1 and lm.manifest["gi"]["sun_radius"] == 0.27
    want = bake_lightmap(net, lights, res=RES, bounces=1, sun_radius=0.27)
    assert np.array_equal(lm.atlas, want.atlas)
    for bad in (["--bounces", "-1"], ["--bounces", "x"], ["--sun-radius", "nan"], ["--sun-radius", "11"],
                ["--tracer", "optix"]):
        with pytest.raises(SystemExit) as exc:
            main([*args[:-4], *bad])
        assert exc.value.code == 2
    capsys.readouterr()
    assert main([*args[:-4], "--tracer", "embree"]) == 1  # without --bounces: a one-line error
    assert "--tracer embree chooses the gather rays of --bounces" in capsys.readouterr().err

    (tmp_path / "net.bpt").write_text("1\n3 3\n" + "0 0 0\n" * 16)
    head = '[terrain]\nsource = "net.bpt"\n[lightmap]\n'
    s = loads_scene(head + "bounces = 2\nsun_radius = 0.27\n", tmp_path / "s.toml")
    assert (s.lightmap.bounces, s.lightmap.sun_radius) == (2, 0.27)
    s = loads_scene(head, tmp_path / "s.toml")
    assert (s.lightmap.bounces, s.lightmap.sun_radius) == (0, 0.0)
    for bad, key in (("bounces = -1", "lightmap.bounces"), ("bounces = 1.5", "lightmap.bounces"),
                     ("sun_radius = 12.0", "lightmap.sun_radius"), ('sun_radius = "big"', "lightmap.sun_radius")):
        with pytest.raises(SceneError) as exc:
            loads_scene(head + bad + "\n", tmp_path / "s.toml")
        assert key in str(exc.value) and "s.toml" in str(exc.value)


def test_embree_tracer_agrees_with_the_exact_one(valley):
    pytest.importorskip("embreex")
    net, lights, pos, nrm, pick = valley
    exact = bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16)
    em = bake_lightmap(net, lights, res=RES, bounces=2, gather_rays=16, tracer="embree")
    assert em.manifest["gi"]["tracer"] == "embree" and "tracer" not in exact.manifest["gi"]
    assert em.manifest["key"] != exact.manifest["key"]
    assert em.stats["gather_rays"] == exact.stats["gather_rays"]
    assert abs(em.stats["gather_escaped"] - exact.stats["gather_escaped"]) <= 1e-3 * exact.stats["gather_rays"]
    d = np.abs(em.atlas - exact.atlas)
    assert d.mean() < 1e-3 and d.max() < 0.02


def test_scene_build_bakes_with_the_lightmap_keys(tmp_path):
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle

    y, x = np.mgrid[0:13, 0:13] * 4.0
    np.savez(tmp_path / "hill.npz", z=20.0 - 0.3 * y + 6.0 * np.sin(x / 9.0), dx=np.float64(4.0))
    text = ('name = "gi"\n[terrain]\nsource = "hill.npz"\n[lightmap]\nres = 8\n{keys}\n[visibility]\nenabled = false\n'
            '[[lights]]\ntype = "ambient"\ncolor = [0.5, 0.6, 0.8]\nintensity = 0.4\n'
            '[[lights]]\ntype = "directional"\ndirection = [0.5, 0.3, -0.5]\nintensity = 1.0\n')
    scene = tmp_path / "gi.toml"
    scene.write_text(text.format(keys=""))
    plain = build_scene(scene)
    first = plain.path.read_bytes()
    a = load_bundle(plain.path)
    assert "bounces" not in a.manifest["lightmap"]
    scene.write_text(text.format(keys="bounces = 1\nsun_radius = 1.0"))
    r = build_scene(scene)
    assert "lightmap" in r.rebuilt and "terrain" in r.cached
    b = load_bundle(r.path)
    assert (b.manifest["lightmap"]["bounces"], b.manifest["lightmap"]["sun_radius"]) == (1, 1.0)
    assert not np.array_equal(a.arrays["lightmap/atlas"], b.arrays["lightmap/atlas"])
    scene.write_text(text.format(keys=""))
    again = build_scene(scene)  # back to the plain keys: the first bake, from the cache
    assert "lightmap" in again.cached and again.path.read_bytes() == first


def test_embree_tracer_on_a_curved_net():
    """Chords stray from curved patches: the lifted origins keep Embree's light close to the exact
    tracer's, far closer than the bounce light itself."""
    pytest.importorskip("embreex")
    net = hill_net(3, 3, relief=-15.0)  # a deep bowl
    lights = Lights((AmbientLight((0.4, 0.5, 0.7), 0.5), DirectionalLight((0.5, 0.2, -0.6))))
    plain = bake_lightmap(net, lights, res=RES)
    exact = bake_lightmap(net, lights, res=RES, bounces=1, gather_rays=16)
    em = bake_lightmap(net, lights, res=RES, bounces=1, gather_rays=16, tracer="embree")
    gi = np.abs(exact.atlas - plain.atlas).mean()
    assert gi > 0.02, gi
    assert np.abs(em.atlas - exact.atlas).mean() < 0.1 * gi
