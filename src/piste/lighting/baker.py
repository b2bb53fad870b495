"""The light-map baker: a deterministic, resumable, parallel pipeline step.

:func:`bake_lightmap` evaluates every patch's ``res x res`` sample points
(:func:`~piste.lighting.lightmap.sample_points`), casts shadow rays
(:func:`~piste.lighting.shadows.shadow_visibility`) and runs the lighting equation
(:func:`~piste.lighting.lights.shade`) in chunks of patches, in a process pool when ``jobs > 1``.

* **Deterministic**: a chunk's result depends only on its patches, the net and the lights (never on
  the worker, the order or the number of jobs); files carry no timestamps; the same input gives
  byte-identical ``lightmap.png``, ``lightmap.npz`` and ``manifest.json``.
* **Resumable**: each finished chunk is written (atomically) to ``partial_dir/<key>/chunk_NNNNN.npy``
  where ``key`` hashes every input; a bake killed half-way and started again reuses those files
  and ends with the same bytes.  The folder is removed after a successful bake.
* **Atomic**: :func:`write_lightmap` writes each file to a temporary name and renames it.

Beyond the game (:mod:`piste.lighting.gi`): ``bounces >= 1`` adds sky light and diffuse
inter-reflection (each chunk also casts its samples' gather rays and keeps where they hit; the
bounces then gather texels over the whole map), ``sun_radius > 0`` makes directional lights area
suns (soft shadows).  Both default to off: the same bytes as before.

:func:`load_or_bake_default_lightmap` is the renderer's entry point: the default course's light
map for the default lights, baked once and cached on disk (in the folder its caller names: piste's
cache root is :func:`piste.pipeline.cache.cache_root`).
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import shutil
import stat
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from piste.errors import FormatError, MissingExtraError, OutputError, ValidationError, describe_os_error
from piste.extras import child_environment
from piste.formats.atomic import atomic_path, write_bytes_atomic
from piste.formats.safe_io import check_regular, loads_json, read_regular
from piste.lighting.lightmap import (LightMap, assemble_atlas, atlas_layout, inputs_key,
                                    sample_points, weld_seam_light)
from piste.lighting.gi import (DEFAULT_ALBEDO, DEFAULT_GATHER_RAYS, TRACERS, EmbreeGather, GatherHits, bounce_light,
                               check_bounces, check_sun_radius, direct_light, gather_hits)
from piste.lighting.lights import Lights, default_lights, light_terms, shade
from piste.lighting.sampling import strata_side
from piste.lighting.shadows import shadow_visibility
from piste.terrain.net import PatchNet
from piste.workers import die_with_parent, kill_pool

__all__ = [
    "BAKE_VERSION",
    "bake_lightmap",
    "partial_usage",
    "clean_partials",
    "kept_chunks_error",
    "write_lightmap",
    "load_lightmap",
    "load_or_bake_default_lightmap",
]

#: bumped whenever the baker's output for the same input changes
BAKE_VERSION = "piste.lightmap-bake/2"  # 2: seams welded (weld_seam_light), fold-aware seam normals
MANIFEST_FORMAT = "piste.lightmap/1"
#: largest light-map file (png / npz) read when verifying a bake folder
MAX_LIGHTMAP_BYTES = 4 << 30
_DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
#: with ``jobs=0`` a bake uses a process pool only from this many samples on
AUTO_PARALLEL_SAMPLES = 300_000
#: environment for worker processes: one BLAS thread each (the pool provides the parallelism)
_WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

# --------------------------------------------------------------------------- chunk work
_STATE: dict = {}


def _init_worker(state: dict) -> None:
    _STATE.clear()
    _STATE.update(state)


def _bake_chunk(chunk: int) -> tuple[int, np.ndarray, dict]:
    """Lighting of the patches of one chunk: ``(chunk, (c, res, res, 3) float32, stats)``.

    With bounces: ``(c, res, res, 3 + 3 rays)`` float32: the direct light ``D`` (unclamped, no
    ambient), then each gather ray's hit patch (-1 sky, -2 a back face; exact in float32 below 2**24
    patches), ``u`` and ``v``."""
    s = _STATE
    lo = chunk * s["chunk_size"]
    hi = min(lo + s["chunk_size"], len(s["positions"]))
    res = s["res"]
    pos = s["positions"][lo:hi].reshape(-1, 3)
    nrm = s["normals"][lo:hi].reshape(-1, 3)
    lights = s["lights"]
    stats: dict = {}
    shadow = None
    ids = np.arange(lo * res * res, hi * res * res)
    if s["shadows"] and any(light.shadows for light in lights.direct):
        terms = light_terms(lights, pos, nrm)
        shadow = shadow_visibility(s["net"], lights, pos, nrm, terms, stats=stats, sun_radius=s["sun_radius"],
                                   sun_rays=s["sun_rays"], ids=ids, seed=s["seed"])
    if not s["bounces"]:
        colors = shade(lights, pos, nrm, shadow)
        return chunk, colors.reshape(hi - lo, res, res, 3), stats
    rays = s["gather_rays"]
    tracer = None
    if s["tracer"] == "embree":
        if "embree" not in s:  # once per process (the tessellation and Embree's BVH)
            s["embree"] = EmbreeGather(s["net"])
        tracer = s["embree"]
    h = gather_hits(s["net"], pos, nrm, ids, rays, s["seed"], stats=stats, tracer=tracer, patches=ids // (res * res))
    out = np.concatenate([direct_light(lights, pos, nrm, shadow), h.patch, h.u, h.v], axis=1).astype(np.float32)
    return chunk, out.reshape(hi - lo, res, res, 3 + 3 * rays), stats


# --------------------------------------------------------------------------- the bake
def bake_lightmap(
    net: PatchNet,
    lights: Lights,
    res: int = 8,
    gutter: int = 1,
    shadows: bool = True,
    jobs: int = 1,
    chunk_size: int = 64,
    partial_dir: str | os.PathLike[str] | None = None,
    progress: bool = False,
    on_chunk: Callable[[int, int, int], None] | None = None,
    bounces: int = 0,
    sun_radius: float = 0.0,
    *,
    gather_rays: int = DEFAULT_GATHER_RAYS,
    albedo: float = DEFAULT_ALBEDO,
    sun_rays: int = 64,
    seed: int = 0,
    tracer: str = "exact",
    clean_command: str | None = None,
) -> LightMap:
    """Bake a light-map atlas for ``net`` under ``lights``.

    Parameters
    ----------
    net : PatchNet
    lights : Lights
    res : samples (texels) per tile side, 8 or 16 in the talk (any >= 2 works)
    gutter : texels replicated around each tile
    shadows : cast shadow rays against the net (terrain self-shadowing)
    jobs : worker processes (1 = in this process; 0 or None = every core when there are at least
        ``AUTO_PARALLEL_SAMPLES`` samples to bake, else 1: starting workers costs ~1 s)
    chunk_size : patches per chunk (the unit of work and of resuming)
    partial_dir : folder for finished chunks (resuming); None keeps nothing
    progress : show a tqdm progress bar
    on_chunk : optional ``callable(chunk_index, chunks_done, chunks_total)`` called after each
        chunk is stored (tests use it to interrupt a bake)
    bounces : diffuse inter-reflections with sky light (:mod:`piste.lighting.gi`); 0 = the direct
        lighting equation with its ambient term, as before.  Memory (and the resumable chunks on
        disk): ``(3 + 3 gather_rays) * 4`` bytes a sample, 780 at 64 rays (the default course at
        8x8: 128 MB)
    sun_radius : angular radius of the directional lights in degrees (soft shadows; 0 = a hard sun,
        as before; the real sun: :data:`piste.lighting.gi.REAL_SUN_RADIUS`)
    gather_rays, albedo : with bounces: rays per sample (a square number) and the terrain's albedo
    sun_rays : with ``sun_radius``: shadow rays per sample to the sun's disc (a square number; the
        eight rim strata first, all of them in the penumbra only)
    seed : the rays' jitter
    tracer : the gather rays' tracer, ``"exact"`` (the patches) or ``"embree"`` (a tessellation through
        Embree, the ``bench`` extra; near hits again exactly): see :mod:`piste.lighting.gi`
    clean_command : the command a failed bake's message names for removing its kept chunks
        (default ``piste bake --clean``; ``piste build`` names its own)

    Returns
    -------
    LightMap (``atlas (H, W, 3) float32``, ``rects (n, 4) float32``, manifest with statistics).
    """
    res, gutter, chunk_size = int(res), int(gutter), int(chunk_size)
    if chunk_size < 1:
        raise ValidationError(f"bake: chunk_size must be >= 1, got {chunk_size}")
    bounces, sun_radius = check_bounces(bounces), check_sun_radius(sun_radius)
    gi: dict = {}
    if bounces:
        strata_side(gather_rays, "bake: gather_rays")
        if len(net) >= 1 << 24:
            raise ValidationError(f"bake: bounces need fewer than 2**24 patches, the net has {len(net)}")
        a = np.asarray(albedo, dtype=np.float64)
        if a.shape not in ((), (3,)) or not (np.isfinite(a).all() and (a >= 0).all() and (a <= 1).all()):
            raise ValidationError(f"bake: albedo must be a number (or 3) in [0, 1], got {albedo!r}")
        if tracer not in TRACERS:
            raise ValidationError(f"bake: tracer must be one of {', '.join(TRACERS)}, got {tracer!r}")
        gi.update(bounces=bounces, gather_rays=int(gather_rays), albedo=a.tolist(), sky="ambient lights")
        if tracer != "exact":
            gi["tracer"] = tracer
            _check_tracer(tracer)
    if sun_radius > 0.0:
        strata_side(sun_rays, "bake: sun_rays")
        gi.update(sun_radius=sun_radius, sun_rays=int(sun_rays))
    if gi:
        gi["seed"] = int(seed)
    layout = atlas_layout(len(net), res, gutter)
    key = inputs_key(net, lights, res, gutter, shadows, chunk_size, BAKE_VERSION, gi)
    width = 3 + 3 * int(gather_rays) if bounces else 3
    positions, normals = sample_points(net, res)
    n = len(net)
    n_chunks = (n + chunk_size - 1) // chunk_size
    tiles = np.zeros((n, res, res, width), dtype=np.float32)
    done = np.zeros(n_chunks, dtype=bool)
    stats: dict = {}
    part = None
    if partial_dir is not None:
        part = Path(partial_dir) / key
        _remove_stale_partials(Path(partial_dir), key)
        part.mkdir(parents=True, exist_ok=True)
        for c in range(n_chunks):
            f = part / f"chunk_{c:05d}.npy"
            fs = part / f"chunk_{c:05d}.json"
            if f.exists() and fs.exists():
                try:
                    arr = np.load(f, allow_pickle=False)
                    st = json.loads(fs.read_text())
                except Exception:  # a corrupt leftover: redo that chunk
                    continue
                lo, hi = c * chunk_size, min((c + 1) * chunk_size, n)
                if arr.shape == (hi - lo, res, res, width) and arr.dtype == np.float32:
                    tiles[lo:hi] = arr
                    done[c] = True
                    for k_, v_ in st.items():
                        stats[k_] = stats.get(k_, 0) + int(v_)
    resumed = int(done.sum())
    state = dict(
        net=net, lights=lights, res=res, chunk_size=chunk_size, positions=positions, normals=normals,
        shadows=bool(shadows), bounces=bounces, sun_radius=sun_radius, sun_rays=int(sun_rays),
        gather_rays=int(gather_rays), seed=int(seed), tracer=tracer,
    )
    todo = [int(c) for c in np.nonzero(~done)[0]]
    if jobs is None or jobs <= 0:
        jobs = (os.cpu_count() or 1) if len(todo) * chunk_size * res * res >= AUTO_PARALLEL_SAMPLES else 1
    jobs = max(1, min(int(jobs), len(todo) or 1))

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_chunks, initial=resumed, unit="chunk", desc=f"bake {res}x{res}", dynamic_ncols=True)

    n_done = resumed

    def store(c: int, arr: np.ndarray, st: dict) -> None:
        nonlocal n_done
        lo = c * chunk_size
        tiles[lo : lo + len(arr)] = arr
        for k_, v_ in st.items():
            stats[k_] = stats.get(k_, 0) + v_
        if part is not None:
            write_bytes_atomic(part / f"chunk_{c:05d}.json", json.dumps(st, sort_keys=True).encode())
            _save_npy_atomic(part / f"chunk_{c:05d}.npy", arr)
        n_done += 1
        if bar is not None:
            bar.update(1)
        if on_chunk is not None:
            on_chunk(c, n_done, n_chunks)

    try:
        if jobs == 1 or len(todo) <= 1:
            _init_worker(state)
            try:
                for c in todo:
                    store(*_bake_chunk(c))
            finally:
                _STATE.clear()
        else:
            import multiprocessing as mp  # (with the pool: ~15 ms of imports a renderer never needs)
            from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

            with child_environment(_WORKER_ENV):  # inherited by the spawned workers
                # workers are SIGKILLed by the kernel if this process dies (piste.workers)
                pool = ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn"), initializer=die_with_parent,
                                           initargs=(os.getpid(), _init_worker, state))
                pending = {pool.submit(_bake_chunk, c) for c in todo}
            with pool:
                try:
                    while pending:
                        finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                        for fut in sorted(finished, key=lambda f: f.result()[0]):
                            store(*fut.result())
                except BaseException:  # an error, Ctrl-C, a full disk: stop the workers now
                    kill_pool(pool)
                    raise
    except (OutputError, OSError) as exc:
        if part is None:
            raise
        cause = exc if isinstance(exc, OSError) else (exc.__cause__ or exc.__context__)
        if getattr(cause, "errno", None) in _DISK_FULL:
            # a full disk: the finished chunks are what filled it; keeping them for a resume would
            # leave the disk full, so they go, and the message says so
            chunks, size = partial_usage(part)
            shutil.rmtree(part, ignore_errors=True)
            raise OutputError(part, f"the bake stopped ({_reason(exc)}); its {chunks} finished chunks "
                                    f"({_bytes(size)}) were removed from here to free the space") from exc
        err = kept_chunks_error(exc, part, clean_command)
        if err is exc:
            raise
        raise err from exc
    finally:
        if bar is not None:
            bar.close()

    if bounces:
        rays = int(gather_rays)
        flat = tiles.reshape(n * res * res, width)
        hits = GatherHits(flat[:, 3 : 3 + rays].astype(np.int32), flat[:, 3 + rays : 3 + 2 * rays],
                          flat[:, 3 + 2 * rays :])
        direct = tiles[..., :3].astype(np.float64)
        del flat
        tiles = bounce_light(direct, hits, lights.ambient_color(), bounces, albedo,
                             weld=lambda t: weld_seam_light(net, t)).astype(np.float32)
    tiles = weld_seam_light(net, tiles)  # both tiles of every seam hold the same light, folds included
    atlas = assemble_atlas(tiles, layout)
    manifest = {
        "format": MANIFEST_FORMAT,
        "bake": BAKE_VERSION,
        "key": key,
        "net": str(getattr(net, "name", "net")),
        "patches": n,
        "res": res,
        "gutter": gutter,
        "atlas_size": [layout.width, layout.height],
        "layout": {"cols": layout.cols, "rows": layout.rows, "cell": layout.cell},
        "encoding": "lightmap.png: half-bright 8-bit RGB, linear light = texel / 128 (128 = 1.0); "
        "lightmap.npz 'atlas': float32 linear light",
        "uv": "patch parameter (u, v) -> atlas (u0 + u (u1 - u0), v0 + v (v1 - v0)); "
        "row y of the image is v = (y + 0.5) / H",
        "shadows": bool(shadows),
        "chunk_size": chunk_size,
        "chunks": n_chunks,
        "samples": int(n * res * res),
        "lights": _json_safe(lights.to_dict()),
    }
    if gi:  # only when asked for: a default bake's manifest is byte-identical to before
        manifest["gi"] = gi
    manifest["stats"] = {k_: int(v_) for k_, v_ in sorted(stats.items())}
    lm = LightMap(atlas=atlas, rects=layout.rects(), res=res, gutter=gutter, manifest=manifest)
    lm.resumed_chunks = resumed  # type: ignore[attr-defined]
    lm.stats = dict(stats)  # type: ignore[attr-defined]
    return lm


def _check_tracer(tracer: str) -> None:
    """A clear MissingExtraError before any work when the tracer's package is missing."""
    if tracer == "embree":
        try:
            import embreex  # noqa: F401
        except ImportError:
            raise MissingExtraError("bench", "piste bake's Embree tracer", "embreex") from None


def _bytes(n: int) -> str:
    return f"{n / 1e6:.1f} MB, {n:,} bytes" if n >= 1e5 else f"{n:,} bytes"


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OutputError):
        return str(exc)
    if isinstance(exc, OSError):
        return describe_os_error(exc)
    return str(exc) or type(exc).__name__


def partial_usage(partial_dir: str | os.PathLike[str]) -> tuple[int, int]:
    """``(chunks, bytes)`` kept under ``partial_dir`` (a bake's ``.partial`` folder, every input's
    sub-folder): finished chunks (``chunk_NNNNN.npy``) and the bytes of every file there.  Links
    are not followed; a missing folder holds ``(0, 0)``."""
    chunks = size = 0
    root = Path(partial_dir)
    if root.is_symlink() or not root.is_dir():
        return 0, 0
    for dirpath, dirnames, filenames in os.walk(root):  # os.walk does not follow links to folders
        for name in filenames:
            try:
                st = os.lstat(os.path.join(dirpath, name))
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode):
                size += st.st_size
                chunks += name.startswith("chunk_") and name.endswith(".npy")
    return chunks, size


def clean_partials(partial_dir: str | os.PathLike[str]) -> tuple[int, int]:
    """Remove the resumable chunks under ``partial_dir`` (see :func:`partial_usage`); returns the
    ``(chunks, bytes)`` removed.  Only the baker's own files go (``chunk_*.npy`` / ``.json`` and
    their temporary files, then the emptied folders); anything else there is left, and a link
    (``partial_dir`` itself or inside it) is never followed."""
    root = Path(partial_dir)
    chunks, size = partial_usage(root)
    if chunks == 0 and size == 0:
        return 0, 0
    removed_chunks = removed = 0
    for dirpath, _dirnames, filenames in os.walk(root, topdown=False):
        for name in filenames:
            f = os.path.join(dirpath, name)
            try:
                st = os.lstat(f)
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode) and name.startswith(("chunk_", ".chunk_")):
                os.unlink(f)
                removed += st.st_size
                removed_chunks += name.startswith("chunk_") and name.endswith(".npy")
        with contextlib.suppress(OSError):  # not empty (someone else's files): kept
            os.rmdir(dirpath)
    return removed_chunks, removed


def kept_chunks_error(exc: BaseException, partial_dir: str | os.PathLike[str], clean_command: str | None = None) -> BaseException:
    """The error to raise for ``exc`` that stopped a bake (or the write after it) while finished
    chunks are kept under ``partial_dir``: an :class:`OutputError` naming the chunks' folder, their
    count and size, and how to resume or remove them (``clean_command``, the command that removes
    them; default: ``piste bake --clean``); ``exc`` itself when nothing is kept."""
    chunks, size = partial_usage(partial_dir)
    if not chunks:
        return exc
    how = f"`{clean_command}`" if clean_command else "`piste bake --clean` for piste bake's --out"
    return OutputError(partial_dir, f"the bake stopped ({_reason(exc)}); its {chunks} finished chunks "
                                    f"({_bytes(size)}) are kept here: the same command resumes from them, and "
                                    f"deleting this folder ({how}) frees them")


def _remove_stale_partials(partial_dir: Path, key: str) -> None:
    """Remove finished chunks of bakes of *other* inputs (an abandoned bake's chunks would stay
    forever: only the current inputs' chunks are removed when a bake completes)."""
    if not partial_dir.is_dir():
        return
    for d in partial_dir.iterdir():
        if d.name != key and d.is_dir() and not d.is_symlink() and len(d.name) == len(key):
            shutil.rmtree(d, ignore_errors=True)


def _json_safe(x: Any) -> Any:
    """``inf`` (a light's unlimited range) as the string "inf", so the manifest is strict JSON."""
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return "inf" if x > 0 else "-inf"
    return x


def _save_npy_atomic(path: Path, arr: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.lib.format.write_array(fh, np.ascontiguousarray(arr), allow_pickle=False)


# --------------------------------------------------------------------------- files
def _npz_bytes(arrays: dict) -> bytes:
    """A .npz (zip of .npy) with fixed timestamps and order: byte-identical for equal arrays."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            data = io.BytesIO()
            arr = np.asarray(arrays[name])
            np.lib.format.write_array(data, arr if arr.flags.c_contiguous else arr.copy(), allow_pickle=False)
            zf.writestr(info, data.getvalue())
    return buf.getvalue()


def _png_bytes(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image), mode="RGB").save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


def write_lightmap(lm: LightMap, out_dir: str | os.PathLike[str]) -> dict:
    """Write ``lightmap.png`` (half-bright 8-bit), ``lightmap.npz`` (``atlas`` float32, ``rects``,
    ``res``, ``gutter``) and ``manifest.json`` into ``out_dir``, each atomically.

    Returns ``{"png": path, "npz": path, "manifest": path}``.
    """
    import hashlib

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    png = _png_bytes(lm.to_uint8())
    npz = _npz_bytes(
        {
            "atlas": lm.atlas.astype(np.float32),
            "rects": lm.rects.astype(np.float32),
            "res": np.int32(lm.res),
            "gutter": np.int32(lm.gutter),
        }
    )
    manifest = dict(lm.manifest)
    manifest["files"] = {
        "lightmap.png": hashlib.sha256(png).hexdigest(),
        "lightmap.npz": hashlib.sha256(npz).hexdigest(),
    }
    paths = {"png": out / "lightmap.png", "npz": out / "lightmap.npz", "manifest": out / "manifest.json"}
    # the old manifest goes first: a folder interrupted from here on has no manifest (or one whose
    # SHA-256 sums, checked by load_lightmap, refuse mixed old and new files): whole or not at all
    try:
        paths["manifest"].unlink()
    except FileNotFoundError:
        pass
    write_bytes_atomic(paths["png"], png)
    write_bytes_atomic(paths["npz"], npz)
    # the manifest goes last: its presence means the other two are complete
    write_bytes_atomic(paths["manifest"], (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode())
    umask = os.umask(0)
    os.umask(umask)
    for p in paths.values():  # temporary files are created 0600; give the results the usual mode
        os.chmod(p, 0o666 & ~umask)
    return paths


def _verify_sums(out: Path, mpath: Path, manifest: dict) -> None:
    """Check ``lightmap.png`` and ``lightmap.npz`` against the manifest's SHA-256 sums."""
    import hashlib

    files = manifest.get("files")
    if not isinstance(files, dict) or set(files) != {"lightmap.png", "lightmap.npz"}:
        raise FormatError(mpath, "expected the SHA-256 sums of lightmap.png and lightmap.npz", field="files")
    for name, want in sorted(files.items()):
        f = out / name
        try:
            size = check_regular(f, MAX_LIGHTMAP_BYTES, owner=mpath, field=f"files.{name}", what="light-map file")
            h = hashlib.sha256()
            with open(f, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
        except OSError as exc:
            raise FormatError(f, f"cannot read: {exc.strerror or exc}") from None
        if h.hexdigest() != want:
            raise FormatError(f, f"does not match the SHA-256 sum in {mpath.name} ({size} bytes): the folder mixes "
                                 "two bakes (an interrupted bake?); bake again")


def load_lightmap(out_dir: str | os.PathLike[str], verify: bool = True) -> LightMap:
    """Read a light map written by :func:`write_lightmap` (float atlas from the .npz).

    ``verify``: check both files against the manifest's SHA-256 sums first (a folder whose bake
    was interrupted between its renames is refused, not read half old, half new)."""
    out = Path(out_dir)
    mpath = out / "manifest.json"
    if not mpath.exists():
        raise FormatError(mpath, "no such file (not a baked light-map folder, or its bake was interrupted)")
    manifest = loads_json(read_regular(mpath, 1 << 24, what="manifest"), mpath)
    if not isinstance(manifest, dict) or manifest.get("format") != MANIFEST_FORMAT:
        got = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise FormatError(mpath, f"expected format {MANIFEST_FORMAT!r}, got {got!r}", field="format")
    if verify:
        _verify_sums(out, mpath, manifest)
    npath = out / "lightmap.npz"
    try:
        with np.load(npath, allow_pickle=False) as data:
            for k in ("atlas", "rects", "res", "gutter"):
                if k not in data.files:
                    raise FormatError(npath, "missing array", field=k)
            return LightMap(
                atlas=data["atlas"].astype(np.float32),
                rects=data["rects"].astype(np.float32),
                res=int(data["res"]),
                gutter=int(data["gutter"]),
                manifest=manifest,
            )
    except FileNotFoundError:
        raise FormatError(npath, "no such file") from None
    except FormatError:
        raise
    except (OSError, ValueError, TypeError, zipfile.BadZipFile) as exc:  # truncated, old layout, not an npz
        raise FormatError(npath, f"unreadable light map ({type(exc).__name__}: {exc})") from None


def load_or_bake_default_lightmap(
    net: PatchNet, lights: Lights | None = None, res: int = 8, shadows: bool = True, *, cache_dir: str | os.PathLike[str],
    jobs: int = 0, progress: bool = False,
) -> LightMap:
    """The light map of ``net`` (e.g. :func:`piste.world.course.default_course`) under ``lights`` (default:
    :func:`~piste.lighting.lights.default_lights`), from the disk cache or baked and cached.

    The cache entry is ``cache_dir/<inputs hash>/`` (piste's own: ``cache_root() / "lightmaps"``,
    :func:`piste.pipeline.cache.cache_root`), so any
    change to the net, the lights or ``res`` bakes anew.  Set the result on the net with
    ``lm.apply(net)`` (``lightmap_rect``) and upload ``lm.atlas`` (float) or ``lm.to_uint8()``
    (half-bright) as the light-map texture.
    """
    if lights is None:
        lights = default_lights()
    cache = Path(cache_dir)
    key = inputs_key(net, lights, res, 1, shadows, 64, BAKE_VERSION)
    entry = cache / key
    if (entry / "manifest.json").exists():
        try:
            lm = load_lightmap(entry)
            if lm.manifest.get("key") == key and lm.rects.shape == (len(net), 4):
                return lm
        except FormatError:
            pass
    lm = bake_lightmap(net, lights, res=res, shadows=shadows, jobs=jobs, partial_dir=cache / ".partial", progress=progress)
    write_lightmap(lm, entry)
    shutil.rmtree(cache / ".partial" / key, ignore_errors=True)
    return lm
