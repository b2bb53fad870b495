"""Large-world benchmark: tiled builds of synthetic worlds, locally and on a 2-worker Dask LocalCluster.

    python benchmarks/bench_large.py [--quick] [--sizes 10000 100000] [--million] [--workers 2]
                                     [--res 4] [--no-shadows] [--frames 60] [--repeats 1]
                                     [--dem [SIDE]] [--dem-only] [--dem-dtype float32|uint16]
                                     [--low-views N] [--cut-far M]

For every size (patches; a square world at 3 samples a patch side, 10 m spacing, tiles of 64 x 64
patches) it builds the world from scratch in a child process -- fit, bake (light maps with shadow
rays against the 3 x 3 tile neighbourhood), far field -- once in this machine's process and once
as Dask tasks on a LocalCluster of ``--workers`` worker processes on 127.0.0.1, interleaved, and
prints build time (median and range over ``--repeats``), peak RSS (the build process; for Dask the
client and the largest worker), the Dask/local time ratio, bake samples/s per worker, the scaling
exponent of build time in patches (a least-squares slope of log time over log patches; 1.0 =
linear) and streaming frame times flying across the largest world at 100 m/s (headless EGL,
``--frames`` frames: 'live', the loader thread paging while frames go on, and 'waited', every near tile
loaded before its frame, interleaved frame by frame with the default course's frame; each streamed
frame split into paging, GL calls and GPU + read-back).  The tiles of the
Dask build are compared byte for byte with the local ones.

The streamed frame's ratio to the course is then split into content and streaming (``--cut-far M``,
default 3,000 m; 0: not): two more renderers join the interleaved rotation, the waited flight with
its far plane at M ('cut') and the same surface within M as one net (the world's fitted patches
that any of those frusta meet, :func:`piste.render.streaming.window_net`) drawn by the bundle
runtime's terrain renderer with the same cameras ('bundle').  waited / course = (waited / cut:
terrain beyond M) x (cut / bundle: streaming against the bundle runtime on the same content) x
(bundle / course: this world's terrain within M against the course's, the same runtime); each
with its frame, Python, draw calls + GPU + read-back and triangles.

The Dask time excludes starting the cluster and the workers' first imports (printed beside it).
``--million`` adds the 1,000,000-patch world (3,001 x 3,001 samples): minutes on 2 cores.
``--quick``: 10,000 patches only, 2 x 2-texel light maps, 10 frames.
``--dem [SIDE]`` (``--dem-only`` for it alone): a SIDE x SIDE (default 20,000) tiled GeoTIFF DEM is
written to the temp folder by tifffile (float32 or ``--dem-dtype uint16``, never kept) and fitted
tile by tile in a child process through windowed reads (4 samples a patch, tiles of
``--dem-tile-patches``): time and peak RSS, which stay those of one tile, not of the DEM.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _timing import record  # noqa: E402


def _child(argv) -> None:
    """``--_child MODE ROOT SIDE RES SHADOWS WORKERS``: one build in a fresh process; prints JSON."""
    mode, root, side, res, shadows, workers = argv
    from piste.pipeline.tiled_build import build_tiles, synthetic_spec

    spec = synthetic_spec(root, int(side), tile_patches=64, res=int(res), shadows=shadows == "1", spacing=10.0)
    t0 = time.perf_counter()
    out = {"mode": mode}
    if mode == "local":
        r = build_tiles(spec)
    else:
        from piste.pipeline.dask_build import build_tiles_dask, close_client, dask_client

        t_start = time.perf_counter()
        client = dask_client("local", workers=int(workers))
        try:
            client.run(_warm_worker)  # every worker imports piste and scipy once
            out["startup_s"] = time.perf_counter() - t_start
            t0 = time.perf_counter()  # cluster start-up and worker imports excluded (reported separately)
            r = build_tiles_dask(spec, client)
            rss = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
            out["worker_rss_mb"] = max(rss.values()) / 1024
        finally:
            close_client(client)
    out["seconds"] = time.perf_counter() - t0
    out["rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["patches"] = spec.grid.n_patches
    out["tiles"] = len(spec.grid.tiles())
    out["samples"] = sum(v.get("samples", 0) for v in r.lit.values())
    out["bake_task_seconds"] = sum(v["seconds"] for v in r.lit.values())
    out["fit_task_seconds"] = sum(v["seconds"] for v in r.fit.values())
    print(json.dumps(out))


def _dem_heights(side: int):
    """A cheap smooth range for ``side x side`` samples at 10 m: window function of global indices."""
    import numpy as np

    def window(rows: slice, cols: slice):
        y = np.arange(rows.start, rows.stop, dtype=np.float64) * 10.0
        x = np.arange(cols.start, cols.stop, dtype=np.float64) * 10.0
        return (800.0 + 300.0 * np.sin(x / 2300.0)[None, :] + 250.0 * np.cos(y / 1700.0)[:, None]
                + 120.0 * np.sin(x / 410.0)[None, :] * np.cos(y / 530.0)[:, None])

    return window


def _peak_rss_mb() -> float:
    """This process's peak resident set (MB): VmHWM, which exec resets (ru_maxrss keeps the forking
    parent's peak on Linux), else ru_maxrss."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _dem_child(argv) -> None:
    """``--_dem PATH TILE_PATCHES``: fit a GeoTIFF DEM tile by tile in a fresh process (windowed
    reads; each tile's control points are computed and dropped); prints JSON."""
    path, tile_patches = argv
    import tracemalloc

    from piste.pipeline.tiled_build import FileSource
    from piste.terrain.heightfield import single_threaded
    from piste.terrain.tiles import TileGrid, fit_tile
    from piste.world.scene_file import TerrainSpec

    rss0 = _peak_rss_mb()
    tracemalloc.start()
    t0 = time.perf_counter()
    src = FileSource(TerrainSpec(kind="geotiff", path=Path(path), samples_per_patch=4, tile_patches=int(tile_patches)))
    grid = TileGrid(src.shape, 4, int(tile_patches), src.spacing)
    read_s = fit_s = 0.0
    patches = 0
    for ty, tx in grid.tiles():
        rows, cols = grid.sample_window(ty, tx)
        t1 = time.perf_counter()
        window = src.window(rows, cols)
        t2 = time.perf_counter()
        with single_threaded():
            cp = fit_tile(grid, ty, tx, window)["control_points"]
        fit_s += time.perf_counter() - t2
        read_s += t2 - t1
        patches += len(cp)
        del cp, window
    seconds = time.perf_counter() - t0
    traced_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(json.dumps({"seconds": seconds, "read_s": read_s, "fit_s": fit_s, "patches": patches,
                      "tiles": len(grid.tiles()), "shape": list(src.shape),
                      "rss_mb": _peak_rss_mb(), "rss_after_imports_mb": rss0, "traced_peak_mb": traced_peak / 2**20}))


def _dem(tmp: Path, side: int, dtype: str, tile_patches: int) -> None:
    """Write a ``side x side`` tiled GeoTIFF (into ``tmp``, deleted afterwards) and fit it tile by tile
    in a child process: time and peak memory, which should not grow with ``side``."""
    from piste.formats.geotiff import write_geotiff_tiled

    flags = f"--dem {side} --dem-dtype {dtype} --dem-tile-patches {tile_patches}"
    path = tmp / f"dem_{side}.tif"
    t0 = time.perf_counter()
    write_geotiff_tiled(path, (side, side), _dem_heights(side), 10.0, tile=(256, 256), dtype=dtype)
    wrote = time.perf_counter() - t0
    size_mb = path.stat().st_size / 2**20
    whole_mb = side * side * 8 / 2**20  # what read_geotiff would hold (float64), before filling
    print(f"\nDEM {side:,} x {side:,} {dtype} tiled GeoTIFF (256 x 256 tiles): {size_mb:,.0f} MiB on disk, written in "
          f"{wrote:.1f} s (a whole-raster read would hold {whole_mb:,.0f} MiB of float64)  [{flags}]")
    cmd = [sys.executable, __file__, "--_dem", str(path), str(tile_patches)]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    path.unlink()
    if p.returncode != 0:
        raise SystemExit(f"DEM fit failed:\n{p.stderr[-3000:]}")
    r = json.loads(p.stdout.strip().splitlines()[-1])
    print(f"  fitted tile by tile: {r['patches']:,} patches in {r['tiles']:,} tiles, {r['seconds']:.1f} s (window reads "
          f"{r['read_s']:.1f} s, fits {r['fit_s']:.1f} s); peak RSS {r['rss_mb']:.0f} MB (after imports "
          f"{r['rss_after_imports_mb']:.0f} MB), tracemalloc peak {r['traced_peak_mb']:.1f} MiB  [{flags}]")
    record("large", f"{side:,}^2 {dtype} GeoTIFF DEM fitted tile by tile (windowed reads) [{flags}]", "",
           f"{r['seconds']:.1f} s", f"peak RSS {r['rss_mb']:.0f} MB, traced {r['traced_peak_mb']:.1f} MiB", "")


def _warm_worker() -> None:
    import piste.pipeline.tiled_build  # noqa: F401
    import scipy.sparse.csgraph  # noqa: F401
    import scipy.spatial  # noqa: F401


def _run_child(mode, root, side, res, shadows, workers) -> dict:
    shutil.rmtree(root, ignore_errors=True)
    cmd = [sys.executable, __file__, "--_child", mode, str(root), str(side), str(res), "1" if shadows else "0",
           str(workers)]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise SystemExit(f"{mode} build failed:\n{p.stderr[-3000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def _files(root: Path) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _med(xs) -> str:
    xs = sorted(xs)
    m = xs[len(xs) // 2]
    return f"{m:8.2f} s [{xs[0]:.2f}..{xs[-1]:.2f}]"


def main(argv=None) -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--_child":
        _child(sys.argv[2:])
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--_dem":
        _dem_child(sys.argv[2:])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--quick", action="store_true", help="10k patches, 2x2 texels, 10 frames")
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000], help="world sizes in patches")
    ap.add_argument("--million", action="store_true", help="also the 1,000,000-patch world")
    ap.add_argument("--workers", type=int, default=2, help="Dask LocalCluster worker processes (default 2)")
    ap.add_argument("--res", type=int, default=4, help="light-map texels a patch side (default 4)")
    ap.add_argument("--no-shadows", action="store_true", help="bake without shadow rays")
    ap.add_argument("--no-dask", action="store_true", help="local builds only")
    ap.add_argument("--frames", type=int, default=60, help="streaming frames (default 60; 0 = none)")
    ap.add_argument("--repeats", type=int, default=1, help="builds of each kind and size (default 1)")
    ap.add_argument("--keep", metavar="DIR", help="build into DIR and keep the worlds")
    ap.add_argument("--reuse", action="store_true",
                    help="with --keep DIR: worlds already built there (local_SIDE/index.json) are streamed, not rebuilt "
                         "(no build figures for them)")
    ap.add_argument("--dem", type=int, nargs="?", const=20_000, metavar="SIDE",
                    help="also write a SIDE x SIDE tiled GeoTIFF DEM (default 20,000) to the temp folder and fit it "
                         "tile by tile (windowed reads): time and peak RSS")
    ap.add_argument("--dem-only", action="store_true", help="only the DEM benchmark (with --dem)")
    ap.add_argument("--dem-dtype", choices=["float32", "uint16"], default="float32", help="the DEM's sample type")
    ap.add_argument("--low-views", type=int, default=0, metavar="N",
                    help="also render N random low views of the largest world (eyes 10-120 m over its top, "
                         "looking 22 degrees down, far 6 km) and check every background pixel under terrain "
                         "along its ray against the exact surface: a crack or sky past the edge or far plane")
    ap.add_argument("--cut-far", type=float, default=3000.0, metavar="M",
                    help="split the streamed frame's ratio to the course into content and streaming: also time the "
                         "flight with its far plane at M metres, and the same surface within M as one net drawn by the "
                         "bundle runtime (default 3000; 0: not)")
    ap.add_argument("--dem-tile-patches", type=int, default=64, help="patches a tile side for the DEM fit (default 64)")
    args = ap.parse_args(argv)
    sizes = [10_000] if args.quick else list(args.sizes)
    if args.million and 1_000_000 not in sizes:
        sizes.append(1_000_000)
    res = 2 if args.quick else args.res
    frames = 10 if args.quick else args.frames
    shadows = not args.no_shadows
    # printed with every figure: the build's settings, as the command line that reproduces them
    flags = f"--res {res}{'' if shadows else ' --no-shadows'}{' (--quick)' if args.quick else ''}"
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_large_"))
    if args.reuse and not args.keep:
        ap.error("--reuse needs --keep DIR")
    if args.dem_only:
        if not args.dem:
            ap.error("--dem-only needs --dem [SIDE]")
        sizes, frames = [], 0
    print(f"bench_large: sizes {sizes}, light maps {res}x{res}, shadows {shadows}, Dask workers "
          f"{0 if args.no_dask else args.workers}, DEM {args.dem or 'none'}, {os.cpu_count()} cores "
          "(timings on a shared machine are noisy)")
    rows = []
    try:
        for n in sizes:
            side = int(round(math.sqrt(n)))
            built = tmp / f"local_{side}" / "index.json"
            if args.reuse and built.is_file():
                idx = json.loads(built.read_text())
                rows.append({"patches": int(idx["patches"]), "tiles": len(idx["tiles"]), "local_s": []})
                print(f"\n{rows[-1]['patches']:>9,} patches ({rows[-1]['tiles']} tiles): reused {built.parent} "
                      f"(res {idx.get('res')}, shadows {idx.get('shadows')}), not rebuilt")
                continue
            runs = {"local": [], "dask": []}
            for _ in range(args.repeats):  # interleaved: local, dask, local, dask, ...
                runs["local"].append(_run_child("local", tmp / f"local_{side}", side, res, shadows, args.workers))
                if not args.no_dask:
                    runs["dask"].append(_run_child("dask", tmp / f"dask_{side}", side, res, shadows, args.workers))
            same = None
            if not args.no_dask:
                same = _files(tmp / f"local_{side}") == _files(tmp / f"dask_{side}")
            loc = runs["local"]
            r0 = loc[0]
            line = {"patches": r0["patches"], "tiles": r0["tiles"], "local_s": [r["seconds"] for r in loc],
                    "local_rss_mb": max(r["rss_mb"] for r in loc),
                    "bake_sps": r0["samples"] / max(r0["bake_task_seconds"], 1e-9)}
            print(f"\n{r0['patches']:>9,} patches ({r0['tiles']} tiles):")
            print(f"  local   build {_med(line['local_s'])}  peak RSS {line['local_rss_mb']:7.0f} MB  "
                  f"bake {line['bake_sps']:,.0f} samples/s (1 process)  [{flags}]")
            med = sorted(line["local_s"])[len(loc) // 2]
            record("large", f"{r0['patches']:,}-patch world built from scratch, local [{flags}]", "",
                   f"{med:.1f} s", f"peak RSS {line['local_rss_mb']:.0f} MB", "")
            if runs["dask"]:
                dk = runs["dask"]
                line["dask_s"] = [r["seconds"] for r in dk]
                wsps = dk[0]["samples"] / max(dk[0]["bake_task_seconds"], 1e-9)
                ratio = sorted(line["dask_s"])[len(dk) // 2] / sorted(line["local_s"])[len(loc) // 2]
                print(f"  dask    build {_med(line['dask_s'])}  peak RSS client {max(r['rss_mb'] for r in dk):5.0f} MB"
                      f", worker {max(r['worker_rss_mb'] for r in dk):5.0f} MB  bake {wsps:,.0f} samples/s per worker"
                      f" (cluster start + worker imports {dk[0]['startup_s']:.1f} s, not counted)  [{flags}]")
                print(f"  dask / local time ratio {ratio:.2f} ({args.workers} workers); tiles byte-identical: {same}")
            rows.append(line)
        timed = [r for r in rows if r["local_s"]]
        if len(timed) > 1:
            import numpy as np

            x = np.log([r["patches"] for r in timed])
            y = np.log([sorted(r["local_s"])[len(r["local_s"]) // 2] for r in timed])
            slope = float(np.polyfit(x, y, 1)[0])
            print(f"\nscaling exponent (local build time ~ patches^k): k = {slope:.2f}  [{flags}]")
        if frames > 0:
            _streaming(tmp, rows, frames, flags, args.cut_far or None)
        if args.low_views and rows:
            _low_views(tmp, rows[-1], args.low_views, flags)
        if args.dem:
            _dem(tmp, args.dem, args.dem_dtype, args.dem_tile_patches)
    finally:
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)


def _streamed_frame(s, wait: bool, cam, k: int, times: list, split: dict, tris: list, calls: dict | None = None) -> None:
    """One frame of StreamingRenderer ``s`` (its own GL context) split into paging (``update``, the
    wait included), GL calls (``submit``) and GPU work with the read-back (``gpu``); frames 0 and 1
    are warm-up (not recorded).  ``calls``: lists of the frame's GL work counts (draw calls, indirect
    commands, light-map binds, uniform writes, culling switches; :attr:`StreamingRenderer.stats`)."""
    with s.ctx:
        t0 = time.perf_counter()
        c = cam.with_aspect(*s.size)
        s.update(c, wait=wait)
        t1 = time.perf_counter()
        s.draw(c, read=False, t0=t0)
        t2 = time.perf_counter()
        s.ctx.finish()
        s.fbo.read()
        t3 = time.perf_counter()
    if k >= 2:
        times.append((t3 - t0) * 1e3)
        for key, a, b in (("update", t0, t1), ("submit", t1, t2), ("gpu", t2, t3)):
            split[key].append((b - a) * 1e3)
        if "driver" in split:  # the draw calls within submit (llvmpipe shades and bins vertices in them)
            split["driver"].append(s.stats.get("draw_ms", 0.0))
        tris.append(s.stats["triangles"])
        for key in (calls or {}):
            calls[key].append(s.stats.get(key, 0))


def _course_frame(course, line, u: float, k: int, times: list, tris: list, split: dict | None = None) -> None:
    """One frame of the default course's terrain at track parameter ``u`` (recorded from frame 2);
    ``split``: its ``python`` (cull, LOD, index lists, upload) and ``gpu`` (GL calls, glFinish and
    the read-back) milliseconds (:class:`piste.render.frame.Frame` ``timings``)."""
    from piste.world.camera import track_camera

    with course.ctx:
        t0 = time.perf_counter()
        f = course.render(track_camera(line, u, aspect=640 / 448))
        t1 = time.perf_counter()
    if k >= 2:
        times.append((t1 - t0) * 1e3)
        tris.append(f.triangles)
        if split is not None:
            split["python"].append(f.timings["cpu"])
            split["gpu"].append(f.timings["gpu"])


def _bundle_frame(tr, cam, k: int, times: list, tris: list, split: dict) -> None:
    """One frame of :class:`piste.render.TerrainRenderer` ``tr`` (the bundle runtime's terrain, its
    own GL context) from ``cam``, read back; recorded from frame 2 like :func:`_course_frame`."""
    with tr.ctx:
        t0 = time.perf_counter()
        f = tr.render(cam)
        t1 = time.perf_counter()
    if k >= 2:
        times.append((t1 - t0) * 1e3)
        tris.append(f.triangles)
        split["python"].append(f.timings["cpu"])
        split["gpu"].append(f.timings["gpu"])


def _low_views(tmp: Path, row: dict, n: int, flags: str = "", seed: int = 0) -> None:
    """Background pixels under terrain (background with terrain above it in its column) in ``n``
    random low views of a world (the cameras of tests/render/test_streaming_lod.py), each pixel's
    ray marched every 2 m against the exact surface of the tiles (their fitted patches): a ray that
    goes below the surface by more than the far levels' error at that distance (``pixel_error``
    pixels) + 1 m is a crack (it should have met terrain), one below it by less grazes a ridge the
    coarser levels lie under (a silhouette of the levels), one that leaves the world or reaches the
    far plane over it is background rightly seen past the world's edge or far plane."""
    import numpy as np

    from piste.render import StreamingRenderer
    from piste.terrain.query import height_at
    from piste.terrain.tiles import tile_net
    from piste.world.camera import Camera

    side = int(round(math.sqrt(row["patches"])))
    r = StreamingRenderer(tmp / f"local_{side}", size=(640, 448), background=(1.0, 0.0, 1.0), sky=False)
    nets: dict = {}
    try:
        rng = np.random.default_rng(seed)
        lo, hi = r.cache.lo.min(0), r.cache.hi.max(0)
        counts = {"pixels": 0, "views": 0, "crack": 0, "graze": 0, "past the edge": 0,
                  "past the far plane": 0}
        deepest = 0.0
        for _ in range(n):
            x, y = rng.uniform(lo[:2] + 200.0, hi[:2] - 200.0)
            a = rng.uniform(0.0, 2.0 * np.pi)
            eye = np.array([x, y, hi[2] + rng.uniform(10.0, 120.0)])
            cam = Camera(eye, eye + np.array([np.cos(a), np.sin(a), 0.0]) * 1500.0 - [0.0, 0.0, 600.0],
                         near=1.0, far=6000.0)
            bg = (r.render(cam, wait=True) == (255, 0, 255)).all(-1)
            above = np.maximum.accumulate(~bg, axis=0)
            under = bg & np.vstack([np.zeros((1, bg.shape[1]), bool), above[:-1]])
            counts["pixels"] += int(under.sum())
            counts["views"] += bool(under.any())
            c = cam.with_aspect(640, 448)
            inv = np.linalg.inv(c.view_projection())
            ts = np.arange(c.near, c.far, 2.0)
            for py, px in np.argwhere(under):
                ndc = [(px + 0.5) / 640 * 2 - 1, 1 - (py + 0.5) / 448 * 2]
                p0, p1 = inv @ [*ndc, -1.0, 1.0], inv @ [*ndc, 1.0, 1.0]
                d = p1[:3] / p1[3] - p0[:3] / p0[3]
                p = c.eye + ts[:, None] * (d / np.linalg.norm(d))
                z = np.full(len(p), np.nan)
                tiles = {}
                for i, (qx, qy) in enumerate(p[:, :2]):
                    try:
                        t = r.cache.grid.tile_of(float(qx), float(qy))
                    except Exception:  # (outside the grid)
                        continue
                    if t in r.cache.tile_index:
                        tiles.setdefault(t, []).append(i)
                for t, ii in tiles.items():
                    if t not in nets:
                        nets[t] = tile_net(r.cache.store, *t)
                    z[ii] = height_at(nets[t], p[ii, :2])[0]
                below = z - p[:, 2]  # metres the ray is under the exact surface
                # (the far levels may lie below the surface by their error: pixel_error pixels at the distance)
                allowed = ts * float(r.far_pixel_error) / r.lod_scale(c.fov_y) + 1.0
                if (below > allowed).any():
                    counts["crack"] += 1
                    deepest = max(deepest, float(np.nanmax(below)))
                elif (below > 1.0).any():
                    counts["graze"] += 1
                elif np.isnan(z).any():
                    counts["past the edge"] += 1
                else:
                    counts["past the far plane"] += 1
        print(f"\nlow views: {n} random low views of the {row['patches']:,}-patch world (eyes 10-120 m over its "
              f"top, 22 degrees down, far 6 km): {counts['pixels']:,} background pixels under terrain in "
              f"{counts['views']} views; along their rays {counts['crack']} go under the exact surface by more than "
              f"the far levels' error there + 1 m (cracks, deepest {deepest:.1f} m), "
              f"{counts['graze']} graze it within that error (silhouettes of the "
              f"levels), {counts['past the edge']} leave the world over it, {counts['past the far plane']} "
              f"reach the far plane over it  [{flags}]")
    finally:
        r.close()


def _streaming(tmp: Path, rows, frames: int, flags: str = "", cut_far: float | None = 3000.0) -> None:
    """Frame times flying across each world: a 'live' renderer (the loader thread pages tiles while
    frames go on), a 'waited' one (each frame waits for its near tiles) and the default course's
    terrain frame (:class:`piste.render.TerrainRenderer`, same size, along its track), each in its own
    GL context, interleaved frame by frame (their order rotated every frame), so they share the
    machine's load alike.  Each streamed frame is split into paging (``update``, the wait included),
    the GL calls (``submit``) and the GPU's work with the read-back (``gpu``: glFinish + read).

    With ``cut_far`` (metres) two more renderers join the rotation, to split the streamed frame's
    ratio to the course into content and streaming: 'cut', the waited streamed frame with the far
    plane at ``cut_far``, and 'bundle', the same cameras over the same surface within ``cut_far``
    (the world's fitted patches any of those frusta meet, :func:`piste.render.streaming.window_net`) drawn as one net by the
    bundle runtime's terrain renderer.  waited / course = (waited / cut: terrain beyond ``cut_far``)
    x (cut / bundle: streaming against the bundle runtime, the same content) x (bundle / course: this
    world's terrain within ``cut_far`` against the course's, the same runtime)."""
    import numpy as np

    from piste.render import StreamingRenderer, TerrainRenderer
    from piste.render.streaming import fly_path, window_net
    from piste.world.course import default_course, track_centerline

    print(f"\nstreaming: {frames} frames flying at 100 m/s, 640x448, headless EGL (llvmpipe), pixels read back; "
          "'live': the loader thread pages tiles while frames go on (far stand-ins until loaded), 'waited': each "
          "frame waits for its near tiles; interleaved frame by frame with the default course (2,560 patches, "
          "TerrainRenderer along its track)"
          + ("" if not cut_far else f", 'cut' (waited, far plane {cut_far:,.0f} m) and 'bundle' (the same "
             f"surface within {cut_far:,.0f} m as one net, TerrainRenderer, the same cameras)") + ", in a rotating order")
    line = track_centerline(0)
    course = TerrainRenderer(default_course(0), size=(640, 448))
    try:
        for r in rows:
            side = int(round(math.sqrt(r["patches"])))
            root = tmp / f"local_{side}"
            names = ("live", "waited", "course") + (("cut", "bundle") if cut_far else ())
            streamed = [n for n in ("live", "waited", "cut") if n in names]
            # 'cut' shares the waited renderer's GL context and 'bundle' the course's (each llvmpipe context
            # has its own rasterizer threads: five of them on 2 cores slowed every frame ~1.6x)
            rs = {name: StreamingRenderer(root, size=(640, 448), budget_bytes=256 << 20) for name in ("live", "waited")}
            if "cut" in streamed:
                with rs["waited"].ctx:  # (GL objects are made in the current context)
                    rs["cut"] = StreamingRenderer(root, size=(640, 448), budget_bytes=256 << 20, ctx=rs["waited"].ctx)
            bundle = None
            t: dict = {k: [] for k in names}
            split = {k: {"update": [], "submit": [], "gpu": [], "driver": []} for k in streamed}
            bsplit = {k: {"python": [], "gpu": []} for k in ("course", "bundle")}
            tris: dict = {k: [] for k in names}
            calls = {k: {n: [] for n in ("draws", "commands", "light_binds", "uniform_writes", "cull_switches",
                                           "far_block_triangles")}
                     for k in streamed}
            resident = 0
            try:
                cams = list(fly_path(rs["live"].cache.index, frames + 2))
                cut = list(fly_path(rs["live"].cache.index, frames + 2, far=cut_far)) if cut_far else []
                if cut_far:
                    t0 = time.perf_counter()
                    net = window_net(root, cut)
                    with course.ctx:
                        bundle = TerrainRenderer(net, size=(640, 448), ctx=course.ctx)
                        bundle.render(cut[0])  # its resident vertex blocks built before the timed frames
                    print(f"  'bundle': {len(net):,} patches of the {r['patches']:,} meet a frustum of the path within "
                          f"{cut_far:,.0f} m; net and resident blocks "
                          f"{time.perf_counter() - t0:.1f} s  [{flags}]")

                for k, cam in enumerate(cams):
                    for j in range(len(names)):  # in a rotating order
                        name = names[(k + j) % len(names)]
                        if name == "course":
                            _course_frame(course, line, 0.1 + 0.4 * k / len(cams), k, t[name], tris[name],
                                          bsplit[name])
                        elif name == "bundle":
                            _bundle_frame(bundle, cut[k], k, t[name], tris[name], bsplit[name])
                        else:
                            _streamed_frame(rs[name], name != "live", cut[k] if name == "cut" else cam, k, t[name],
                                            split[name], tris[name], calls[name])
                    resident = max(resident, rs["live"].stats["resident_bytes"], rs["waited"].stats["resident_bytes"])
            finally:
                for s in rs.values():
                    s.close()
                if bundle is not None:
                    bundle.release()

            def med(xs) -> str:
                a = np.asarray(xs, dtype=np.float64)
                return f"{np.median(a):6.1f} ms [{a.min():.1f}..{a.max():.1f}]"

            mc = float(np.median(t["course"]))
            print(f"  {r['patches']:>9,} patches: live frame median {med(t['live'])}, waited {med(t['waited'])}, "
                  f"default course {med(t['course'])}; ratios live {np.median(t['live']) / mc:.2f}, waited "
                  f"{np.median(t['waited']) / mc:.2f}; resident {resident / 2**20:.1f} MiB of 256  [{flags}]")
            for name in streamed:
                sp = split[name]
                work = ", ".join(f"{int(np.median(v)):,} {n.replace('_', ' ')}" for n, v in calls[name].items())
                print(f"    {name:6s} split (medians): paging {np.median(sp['update']):.1f} ms, GL calls "
                      f"{np.median(sp['submit']):.1f} ms (of which draw calls {np.median(sp['driver']):.1f}), "
                      f"GPU + read {np.median(sp['gpu']):.1f} ms; triangles "
                      f"{int(np.median(tris[name])):,} a frame (course {int(np.median(tris['course'])):,}); GL work a "
                      f"frame (medians): {work}  [{flags}]")
            ratio = float(np.median(t["live"])) / mc
            record("large", f"streamed frame, {r['patches']:,}-patch world at 100 m/s (live) vs the default course's "
                   f"[{flags}]", "<= 1.2x", f"{np.median(t['live']):.1f} ms", f"{mc:.1f} ms", f"{ratio:.2f}x",
                   ratio <= 1.2)
            if cut_far:
                _decomposition(r["patches"], cut_far, t, split, bsplit, tris, flags)
    finally:
        course.release()


def _decomposition(patches: int, cut_far: float, t: dict, split: dict, bsplit: dict, tris: dict, flags: str) -> None:
    """Print and record the streamed frame's ratio to the course split into content and streaming
    (see :func:`_streaming`): frame, Python (streamed: paging + GL calls; bundle runtime: cull, LOD,
    index lists, upload) and GPU + read-back medians with ranges, triangles a frame, and the factors."""
    import numpy as np

    def m(xs) -> float:
        return float(np.median(np.asarray(xs, dtype=np.float64)))

    def rng(xs) -> str:
        a = np.asarray(xs, dtype=np.float64)
        return f"{np.median(a):5.1f} ms [{a.min():.1f}..{a.max():.1f}]"

    sp = {n: split[n] for n in ("waited", "cut")}
    py = {n: [a + b - c for a, b, c in zip(v["update"], v["submit"], v["driver"])] for n, v in sp.items()}
    py.update({n: bsplit[n]["python"] for n in bsplit})
    gpu = {n: [a + b for a, b in zip(v["driver"], v["gpu"])] for n, v in sp.items()}
    gpu.update({n: bsplit[n]["gpu"] for n in bsplit})
    what = {"waited": "streamed, far plane of the flight", "cut": f"streamed, far plane {cut_far:,.0f} m",
            "bundle": f"bundle runtime, the same surface within {cut_far:,.0f} m",
            "course": "bundle runtime, the default course"}
    print(f"  decomposition of the {patches:,}-patch world's streamed frame (waited: every near tile loaded) "
          f"against the course's, the same run (medians; Python: paging and the frame's lists, or the bundle "
          f"runtime's cull, LOD, index lists and upload; draw calls: the driver, where llvmpipe shades and bins "
          f"vertices):  [{flags}]")
    for n in ("waited", "cut", "bundle", "course"):
        print(f"    {n:6s} ({what[n]}): frame {rng(t[n])}, Python {m(py[n]):.1f} ms, draw calls + GPU + read "
              f"{m(gpu[n]):.1f} ms, triangles {int(np.median(tris[n])):,}  [{flags}]")
    mw, mcut, mb, mc = (m(t[n]) for n in ("waited", "cut", "bundle", "course"))
    horizon, stream, content = mw / mcut, mcut / mb, mb / mc
    print(f"    waited / course {mw / mc:.2f} = terrain beyond {cut_far:,.0f} m {horizon:.2f} (waited / cut) x "
          f"streaming against the bundle runtime on the same content {stream:.2f} (cut / bundle) x this world's "
          f"terrain within {cut_far:,.0f} m against the course's, same runtime {content:.2f} (bundle / course)  "
          f"[{flags}]")
    base = f"{patches:,}-patch world at 100 m/s"
    record("large", f"streamed frame, {base}, far plane {cut_far:,.0f} m (waited) vs the same surface as one net "
           f"(bundle runtime, same cameras): streaming's own share [{flags}]", "", f"{mcut:.1f} ms", f"{mb:.1f} ms",
           f"{stream:.2f}x")
    record("large", f"content: the same surface within {cut_far:,.0f} m as one net (bundle runtime, the flight's "
           f"cameras) vs the default course's frame [{flags}]", "", f"{mb:.1f} ms", f"{mc:.1f} ms", f"{content:.2f}x")
    record("large", f"content: streamed frame, {base}, its own far plane vs far plane {cut_far:,.0f} m (waited) "
           f"[{flags}]", "", f"{mw:.1f} ms", f"{mcut:.1f} ms", f"{horizon:.2f}x")


if __name__ == "__main__":
    main()
