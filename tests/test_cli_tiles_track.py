"""``piste render WORLD.tiles --track X0 Y0 X1 Y1`` (issue 26): the default pack of riders rides a
straight track across the tiles, the camera chasing rider 0, from the command line; ``--riders N``
sizes the pack (``piste render`` and ``piste view``); the flags' misuses are one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from piste.cli import main
from piste.pipeline.tiled_build import ArraySource, TiledSpec, build_tiles
from piste.terrain.tiles import TileGrid, TileStore

SPP, SP = 3, 10.0


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """6 x 2 tiles of 120 m: a slope falling along +x with rolls across it."""
    root = tmp_path_factory.mktemp("track") / "w.tiles"
    ny, nx = 2 * 4 * SPP + 1, 6 * 4 * SPP + 1
    x, y = np.meshgrid(np.arange(nx) * SP, np.arange(ny) * SP)
    z = 300.0 - 0.3 * x + 4.0 * np.sin(x / 40.0) * np.cos(y / 35.0)
    spec = TiledSpec(str(root), ArraySource(z, (SP, SP)), TileGrid((ny, nx), SPP, 4, (SP, SP)), "", res=2,
                     shadows=False)
    build_tiles(spec)
    return spec


def test_render_track_riders_ride_across_the_tiles(world, tmp_path, monkeypatch, capsys):
    from piste.terrain.net import PatchNet
    from piste.terrain.query import height_at
    from piste.world.scene import Scene

    seen = []  # rider 0's anchor and the camera's eye of every frame the CLI renders
    update = Scene.update

    def spy(self, *a, **kw):
        sf = update(self, *a, **kw)
        seen.append((sf.riders.anchor.copy(), np.asarray(sf.camera.eye, dtype=np.float64)))
        return sf

    monkeypatch.setattr(Scene, "update", spy)
    out = tmp_path / "f.png"
    rc = main(["render", world.root, "--track", "15", "110", "705", "130", "--frames", "31", "--fps", "1",
               "--size", "160", "112", "--out", str(out), "--quiet"])
    assert rc == 0 and out.is_file()
    assert "chasing rider 0 along the track" in capsys.readouterr().out
    assert len(seen) >= 31
    store, g = TileStore(world.root), world.grid
    whole = PatchNet(np.concatenate([store.read_fit(g, *t)["control_points"] for t in g.tiles()]))
    cols = set()
    for anchor, eye in seen:
        z, hit, _, _ = height_at(whole, anchor[:, :2])
        assert hit.all() and np.allclose(anchor[:, 2], z, atol=1e-4)  # every rider on the world's surface
        assert np.linalg.norm(eye[:2] - anchor[0, :2]) < 30.0  # the camera chases rider 0
        cols.add(g.tile_of(*anchor[0, :2])[1])
    assert cols >= {0, 1, 2, 3}  # 30 s at 11 m/s from 12 % along: rider 0 crossed four tile columns
    xs = [a[0, 0] for a, _ in seen]
    assert xs[-1] - xs[0] > 300.0


@pytest.mark.parametrize("args, words", [
    (["--track", "15", "110", "400", "130", "--riders", "64"], "a pack of 64 riders needs more than"),
    (["--track", "15", "110", "9000", "130"], "lies off the world"),
    (["--track", "15", "110", "100", "110"], "needs more than"),
])
def test_render_track_misuses_are_one_line_errors(world, tmp_path, args, words, capsys):
    rc = main(["render", world.root, *args, "--size", "64", "48", "--out", str(tmp_path / "x.png"), "--quiet"])
    err = capsys.readouterr().err
    assert rc != 0 and words in err and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


def test_render_track_needs_a_tiled_world(tmp_path, capsys):
    rc = main(["render", str(tmp_path / "a.piste"), "--track", "0", "0", "500", "0", "--out", str(tmp_path / "x.png")])
    assert rc != 0 and "--track needs a tiled world" in capsys.readouterr().err


def _spy_riders(monkeypatch) -> list:
    """Rider anchors ``(n, 3)`` and the camera's eye of every scene frame drawn."""
    from piste.world.scene import Scene

    seen = []
    update = Scene.update

    def spy(self, *a, **kw):
        sf = update(self, *a, **kw)
        seen.append((sf.riders.anchor.copy(), np.asarray(sf.camera.eye, dtype=np.float64)))
        return sf

    monkeypatch.setattr(Scene, "update", spy)
    return seen


@pytest.mark.parametrize("n", [1, 14])
def test_render_track_riders_n_sizes_the_pack(world, tmp_path, monkeypatch, capsys, n):
    from piste.terrain.net import PatchNet
    from piste.terrain.query import height_at

    seen = _spy_riders(monkeypatch)
    out = tmp_path / "f.png"
    rc = main(["render", world.root, "--track", "15", "110", "705", "130", "--riders", str(n), "--frames", "3",
               "--fps", "2", "--size", "96", "64", "--out", str(out), "--quiet"])
    assert rc == 0 and out.is_file(), capsys.readouterr().err
    assert "chasing rider 0 along the track" in capsys.readouterr().out
    assert seen and all(len(a) == n for a, _ in seen)
    store, g = TileStore(world.root), world.grid
    whole = PatchNet(np.concatenate([store.read_fit(g, *t)["control_points"] for t in g.tiles()]))
    anchor, eye = seen[-1]
    z, hit, _, _ = height_at(whole, anchor[:, :2])
    assert hit.all() and np.allclose(anchor[:, 2], z, atol=1e-4)  # every rider on the world's surface
    assert np.linalg.norm(eye[:2] - anchor[0, :2]) < 30.0
    if n > 1:  # spread down the track, about 8 m apart, none on top of another
        gap = np.linalg.norm(anchor[:, None, :2] - anchor[None, :, :2], axis=2) + 1e3 * np.eye(n)
        assert gap.min() > 2.0 and np.ptp(anchor[:, 0]) > 8.0 * (n - 3)


def test_view_track_riders_n_sizes_the_pack(world, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    seen = _spy_riders(monkeypatch)
    out = tmp_path / "v.png"
    rc = main(["view", world.root, "--track", "15", "110", "705", "130", "--riders", "3", "--size", "96", "64",
               "--out", str(out)])
    assert rc == 0 and out.is_file(), capsys.readouterr().err
    assert seen and all(len(a) == 3 for a, _ in seen)


def test_riders_without_track_on_tiles_still_stand(world, tmp_path, monkeypatch, capsys):
    """(``--riders N`` without ``--track`` stands N riders on the world, as before.)"""
    from piste.pipeline.open_scene import open_source

    b = open_source(world.root, riders=2)
    assert len(b.manifest["riders"]) == 2 and not b.manifest.get("pack")
    b = open_source(world.root, riders=5, track=(15.0, 110.0, 705.0, 130.0))
    assert b.manifest["pack"]["riders"] == 5 and not b.manifest.get("riders")
