"""Tiled builds in this process and on a Dask LocalCluster (loopback only): byte-identical tiles,
resuming without recomputing finished tiles, a clear error naming a failed tile, the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.tiled_build import (ArraySource, SyntheticSource, TileError, TiledSpec, build_tiles,
                                        synthetic_spec)
from piste.terrain.net import PatchNet
from piste.terrain.tiles import TileGrid, TileStore


def _files(root: Path) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_synthetic_source_windows_have_the_bits_of_the_whole_field():
    src = SyntheticSource((61, 73), (10.0, 10.0), seed=4)
    whole = src.window(slice(0, 61), slice(0, 73))
    assert whole.shape == (61, 73) and 0.0 <= whole.min() and whole.max() <= 1500.0 and whole.std() > 50.0
    assert np.array_equal(src.window(slice(17, 40), slice(5, 9)), whole[17:40, 5:9])
    assert not np.array_equal(SyntheticSource((61, 73), (10.0, 10.0), seed=5).window(slice(0, 9), slice(0, 9)),
                              whole[:9, :9])


def test_tiled_build_bakes_every_tile_and_resumes(tmp_path):
    spec = synthetic_spec(tmp_path / "w", 12, tile_patches=4, res=3, spacing=20.0, cell=120.0)
    r = build_tiles(spec)
    assert r.built == 18 and r.skipped == 0
    idx = json.loads((tmp_path / "w" / "index.json").read_text())
    assert idx["patches"] == 144 and len(idx["tiles"]) == 9
    store = TileStore(tmp_path / "w")
    lit = store.read("lit", 1, 1)
    assert lit["texels"].shape == (16, 3, 3, 3) and lit["texels"].dtype == np.uint8
    assert lit["far_positions"].shape == (5, 5, 3) and lit["far_colors"].shape == (5, 5, 3)
    assert lit["vis_patch_bits"].shape[0] > 0
    assert r.lit[(1, 1)]["rays"] > 0  # shadow rays were cast against the neighbourhood
    # the far field's corners are the fitted patch corners: neighbouring tiles share their border row
    right = store.read("lit", 1, 2)["far_positions"]
    assert np.array_equal(lit["far_positions"][:, -1], right[:, 0])
    before = _files(tmp_path / "w")
    # resume: one lit tile lost, one fit tile torn -> exactly those two are recomputed, same bytes
    store.path("lit", 2, 0).unlink()
    p = store.path("fit", 0, 2)
    p.write_bytes(p.read_bytes()[:100])
    r2 = build_tiles(spec)
    assert r2.built == 2 and r2.skipped == 16
    assert _files(tmp_path / "w") == before
    # the welded fitted tiles make one watertight net
    cps = [store.read("fit", *t)["control_points"] for t in spec.grid.tiles()]
    assert len(PatchNet(np.concatenate(cps), tol=1e-9).boundary_edges) == 4 * 12


def test_failed_tile_is_named(tmp_path):
    z = np.zeros((3 * 6 + 1, 3 * 6 + 1))
    z[15, 2] = np.nan
    spec = TiledSpec(str(tmp_path / "bad"), ArraySource(z, (1.0, 1.0)), TileGrid(z.shape, 3, 3, (1.0, 1.0)), res=2)
    with pytest.raises(TileError, match=r"tile \(1, 0\) failed in step 'fit'.*row 15, column 2"):
        build_tiles(spec)
    distributed = pytest.importorskip("distributed")
    from piste.pipeline.dask_build import build_tiles_dask

    with distributed.LocalCluster(n_workers=1, processes=False, protocol="tcp://", host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0") as cluster, distributed.Client(cluster) as client:
        with pytest.raises(TileError, match=r"tile \(1, 0\) failed in step 'fit'.*row 15, column 2"):
            build_tiles_dask(spec, client)


def test_dask_local_cluster_is_byte_identical_and_resumes(tmp_path):
    distributed = pytest.importorskip("distributed")
    from piste.pipeline.dask_build import build_tiles_dask

    local = synthetic_spec(tmp_path / "local", 9, tile_patches=4, res=2, spacing=20.0, cell=90.0)
    build_tiles(local)
    spec = synthetic_spec(tmp_path / "dask", 9, tile_patches=4, res=2, spacing=20.0, cell=90.0)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster, \
            distributed.Client(cluster) as client:
        r = build_tiles_dask(spec, client)
        assert r.built == 18
        assert _files(tmp_path / "dask") == _files(tmp_path / "local")  # byte-identical, index included
        # a killed client leaves finished tiles behind: a new run recomputes only what is missing
        TileStore(spec.root).path("lit", 0, 1).unlink()
        (tmp_path / "dask" / "index.json").unlink()
        r2 = build_tiles_dask(spec, client)
        assert r2.built == 1 and r2.skipped == 17
    assert _files(tmp_path / "dask") == _files(tmp_path / "local")


def test_cli_build_tiled_scene_with_dask_local(tmp_path, capsys):
    pytest.importorskip("distributed")
    from piste.cli import main
    from piste.formats.geotiff import write_geotiff

    z = SyntheticSource((3 * 8 + 1, 3 * 8 + 1), (15.0, 15.0), seed=1).window(slice(0, 25), slice(0, 25))
    write_geotiff(tmp_path / "dem.tif", z, 15.0)
    (tmp_path / "w.toml").write_text('[terrain]\nsource = "dem.tif"\nsamples_per_patch = 3\ntiles = "w.tiles"\n'
                                     "tile_patches = 4\n[lightmap]\nres = 2\n[visibility]\nenabled = false\n")
    assert main(["build", str(tmp_path / "w.toml"), "--quiet"]) == 0
    assert "64 patches in 2 x 2 tiles" in capsys.readouterr().out
    local = _files(tmp_path / "w.tiles")
    assert main(["build", str(tmp_path / "w.toml"), "--quiet", "--dask", "local", "--workers", "1",
                 "--out", str(tmp_path / "d.tiles")]) == 0
    assert "0 reused" in capsys.readouterr().out
    assert _files(tmp_path / "d.tiles") == local
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, protocol="tcp://", host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0") as cluster:  # a "remote" scheduler
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        assert main(["build", str(tmp_path / "w.toml"), "--quiet", "--scheduler", cluster.scheduler_address,
                     "--out", str(tmp_path / "s.tiles")]) == 0
    assert _files(tmp_path / "s.tiles") == local
    assert main(["build", str(tmp_path / "w.toml"), "--quiet", "--dask", "remote"]) == 1
    assert "--dask takes 'local'" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="tcp://HOST"):
        from piste.pipeline.dask_build import dask_client

        dask_client(scheduler="localhost:1")


class _KillOnce(SyntheticSource):
    """A synthetic source whose first read of one window kills the worker process running it."""

    def window(self, rows, cols):
        import os

        marker = Path(os.environ["PISTE_TEST_KILL_MARKER"])
        if rows.start == 12 and cols.start == 12 and not marker.exists():
            marker.write_text("killed")
            os._exit(1)  # the worker dies mid-task, as if killed
        return super().window(rows, cols)


@pytest.mark.slow
def test_killed_worker_resumes_byte_identical(tmp_path, monkeypatch):
    import dataclasses
    import sys

    distributed = pytest.importorskip("distributed")
    import cloudpickle

    from piste.pipeline.dask_build import build_tiles_dask

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    monkeypatch.setenv("PISTE_TEST_KILL_MARKER", str(tmp_path / "killed"))
    local = synthetic_spec(tmp_path / "local", 12, tile_patches=4, res=2, spacing=20.0)
    build_tiles(local)
    spec = synthetic_spec(tmp_path / "dask", 12, tile_patches=4, res=2, spacing=20.0)
    spec.source = _KillOnce(**{f.name: getattr(spec.source, f.name) for f in dataclasses.fields(SyntheticSource)})
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster, \
            distributed.Client(cluster) as client:
        r = build_tiles_dask(spec, client)
    assert (tmp_path / "killed").exists()  # a worker really died (tile (1, 1)'s fit)
    # tasks whose results died with the worker are re-run by Dask; those whose tiles were already
    # written find them on disk and skip the work
    assert r.built + r.skipped == 18 and r.built >= 9
    assert _files(tmp_path / "dask") == _files(tmp_path / "local")


def test_tiled_scene_errors(tmp_path, capsys):
    from piste.cli import main

    (tmp_path / "d.toml").write_text('[terrain]\ntiles = "d.tiles"\n')
    assert main(["build", str(tmp_path / "d.toml"), "--quiet"]) == 1
    assert "needs a height-field terrain" in capsys.readouterr().err
    np.savez(tmp_path / "h.npz", z=np.zeros((13, 13)), dx=1.0)
    (tmp_path / "t.toml").write_text('[terrain]\nsource = "h.npz"\ntiles = "t.tiles"\ntile_patches = 1\n')
    assert main(["build", str(tmp_path / "t.toml"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "terrain.tile_patches" in err and "line 4" in err
    with pytest.raises(ConfigError, match="exactly one of"):
        from piste.pipeline.dask_build import dask_client

        dask_client()


def test_tiled_scene_notes_what_it_leaves_out(tmp_path, capsys):
    from piste.cli import main

    np.savez(tmp_path / "h.npz", z=np.zeros((13, 13)), dx=5.0)
    (tmp_path / "t.toml").write_text('[terrain]\nsource = "h.npz"\nsamples_per_patch = 3\ntiles = "t.tiles"\n'
                                     'tile_patches = 2\n[lightmap]\nres = 2\n[visibility]\nenabled = false\n'
                                     '[[objects]]\nmodel = "builtin:tree"\nposition = [10.0, 10.0]\n')
    assert main(["build", str(tmp_path / "t.toml"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "16 patches in 2 x 2 tiles" in out and "1 riders and objects are not placed" in out


def test_build_bytes_do_not_depend_on_blas_threads(tmp_path):
    """Tiles of 30 x 30 patches are large enough for OpenBLAS to thread their products: unpinned,
    a build in a 2-thread process differed from a single-threaded Dask worker's in the last bits of
    ~1 % of the control points (issue 26 item 7).  The tasks pin BLAS to one thread."""
    distributed = pytest.importorskip("distributed")
    from threadpoolctl import threadpool_limits

    from piste.pipeline.dask_build import build_tiles_dask

    local = synthetic_spec(tmp_path / "local", 60, tile_patches=30, res=2, shadows=True)
    with threadpool_limits(limits=2):  # as a 2-core machine's OpenBLAS runs by default
        build_tiles(local)
    spec = synthetic_spec(tmp_path / "dask", 60, tile_patches=30, res=2, shadows=True)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster, \
            distributed.Client(cluster) as client:
        r = build_tiles_dask(spec, client)
    assert r.built == 8
    assert _files(tmp_path / "dask") == _files(tmp_path / "local")
