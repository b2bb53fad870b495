"""Building a tiled world on a Dask cluster (``dask.distributed``): the same tasks, the same bytes.

``piste build SCENE --dask local`` starts a :class:`distributed.LocalCluster` on 127.0.0.1 (this
machine's cores); ``--scheduler tcp://HOST:PORT`` connects to a running scheduler.  The tasks are
those of :mod:`piste.pipeline.tiled_build`: one ``fit`` task a tile, then one ``lit`` task a tile
that depends on the ``fit`` futures of its 3 x 3 neighbourhood (Dask runs it once they are done).
Each task writes its tile atomically and returns a few numbers, so the client never holds the net.

* **Byte-identical**: a task is a pure function of (spec, tile); where it runs does not matter.
* **Resumable**: a task first checks whether its output exists and verifies (key and zip CRCs);
  a killed worker's tasks are re-run by Dask, a killed client's build run again skips every
  finished tile.  Tasks are ``pure=False`` so that a resumed run really checks the disk.
* **Shared storage**: the workers write to ``spec.root`` themselves: on a real cluster it must be
  a path every worker sees (NFS, a cluster file system), and the height source must be readable
  there too (a GeoTIFF on the shared path, or :class:`~piste.pipeline.tiled_build.SyntheticSource`).

Pointing it at a cluster: start ``dask scheduler`` on one host and ``dask worker tcp://HOST:8786``
on the others (or let dask-jobqueue / dask-kubernetes do it: piste only needs the address), then
``piste build SCENE --scheduler tcp://HOST:8786``.
"""

from __future__ import annotations

import logging
import time
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from piste.errors import ConfigError
from piste.pipeline.tiled_build import (TiledResult, TiledSpec, build_tiles, far_heights_task, fit_task, lit_task,
                                        spec_from_scene,
                                        write_index)

if TYPE_CHECKING:
    from piste.world.scene_file import SceneFile

__all__ = ["dask_client", "close_client", "build_tiles_dask", "build_scene_tiles"]

log = logging.getLogger(__name__)
#: client -> the LocalCluster dask_client started for it (closed with it by close_client)
_CLUSTERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise ConfigError("piste build --dask/--scheduler needs the 'dask' extra: pip install 'piste[dask]'") from None
    return distributed


def dask_client(dask: str | None = None, scheduler: str | None = None, workers: int | None = None,
                threads_per_worker: int = 1, processes: bool = True) -> Any:
    """A :class:`distributed.Client`: ``dask="local"`` starts a LocalCluster on 127.0.0.1 (its
    dashboard on a free loopback port), ``scheduler="tcp://HOST:PORT"`` connects to one.  Close it when done."""
    distributed = _distributed()
    if (dask is None) == (scheduler is None):
        raise ConfigError("give exactly one of --dask local and --scheduler tcp://HOST:PORT")
    if dask is not None:
        if dask != "local":
            raise ConfigError(f"--dask takes 'local' (a LocalCluster on this machine), got {dask!r}; "
                              "for a cluster use --scheduler tcp://HOST:PORT")
        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker,
                                           processes=processes, protocol="tcp://", host="127.0.0.1",
                                           dashboard_address="127.0.0.1:0",
                                           silence_logs=40)
        client = distributed.Client(cluster)
        _CLUSTERS[client] = cluster
        return client
    scheduler = cast(str, scheduler)  # exactly one of the two is given (checked above)
    if not scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://")):
        raise ConfigError(f"--scheduler takes an address like tcp://HOST:8786, got {scheduler!r}")
    try:
        return distributed.Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None


def close_client(client: Any) -> None:
    """Close ``client`` and the local cluster :func:`dask_client` started for it, if any."""
    cluster = _CLUSTERS.pop(client, None)
    client.close()
    if cluster is not None:
        cluster.close()


def build_tiles_dask(spec: TiledSpec, client: Any, progress: bool = False) -> TiledResult:
    """Build every tile of ``spec`` as Dask tasks on ``client``; the index is written here, last.

    Raises :class:`~piste.pipeline.tiled_build.TileError` naming the first tile that failed.
    """
    distributed = _distributed()
    t0 = time.perf_counter()
    g = spec.grid
    spec.store.root.mkdir(parents=True, exist_ok=True)
    spec.source_key()  # hash the source once here, not in every task
    fit_f = {t: client.submit(fit_task, spec, *t, pure=False, key=f"piste-fit-{t[0]}-{t[1]}-{time.time_ns()}")
             for t in g.tiles()}
    lit_f = {}
    # the world's far heights (far-field shadows): after every fit, before every bake
    far_f = client.submit(far_heights_task, spec, *fit_f.values(), pure=False, key=f"piste-far-{time.time_ns()}")
    for ty, tx in g.tiles():
        deps = [fit_f[(y, x)] for y in range(max(ty - 1, 0), min(ty + 2, g.shape[0]))
                for x in range(max(tx - 1, 0), min(tx + 2, g.shape[1]))] + [far_f]
        lit_f[(ty, tx)] = client.submit(lit_task, spec, ty, tx, *deps, pure=False,
                                        key=f"piste-lit-{ty}-{tx}-{time.time_ns()}")
    futures = list(fit_f.values()) + [far_f] + list(lit_f.values())
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(futures), desc="tiles (dask)", unit="task", leave=False)
        if client.dashboard_link:
            log.info("Dask dashboard: %s", client.dashboard_link)
    results = {}
    try:
        for fut in distributed.as_completed(futures):
            results[fut.key] = fut.result()  # re-raises the task's TileError
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        for f in futures:
            f.cancel()
    fits = {t: results[f.key] for t, f in fit_f.items()}
    lits = {t: results[f.key] for t, f in lit_f.items()}
    for d in (fits, lits):
        for r in d.values():
            r["tile"] = tuple(r["tile"])
    index = write_index(spec, fits, lits)
    return TiledResult(spec.store.root, index, time.perf_counter() - t0, fits, lits)


def build_scene_tiles(scene: SceneFile, out: str | Path | None = None, dask: str | None = None, scheduler: str | None = None,
                      workers: int | None = None, progress: bool = False) -> TiledResult:
    """``piste build`` of a scene with a tiled terrain: in this process, or on Dask when ``dask``
    (``"local"``) or ``scheduler`` is given.  ``out``: the tiles folder (default ``terrain.tiles``,
    else the scene's path with suffix ``.tiles``)."""
    spec = spec_from_scene(scene, root=out)
    if dask is None and scheduler is None:
        r = build_tiles(spec, progress=progress)
    else:
        client = dask_client(dask, scheduler, workers=workers)
        try:
            r = build_tiles_dask(spec, client, progress=progress)
        finally:
            close_client(client)
    extra = len(scene.riders) + len(scene.objects)
    if extra:
        r.notes.append(f"a tiled world holds the terrain and its light maps only: the scene's {extra} riders and "
                       "objects are not placed (not supported yet)")
    return r
