"""An SSX Tricky level as something piste can render, bake and export.

:func:`load_level` reads ``LEVEL.pbd`` and, beside it, ``LEVEL.ssh`` (textures) and
``LEVEL_L.ssh`` (light-map pages) when present, and prepares what the terrain renderer takes:

* ``net``: the patches as a :class:`~piste.terrain.net.PatchNet` in metres (welded), its corner
  UVs mapped into ``base_atlas`` (each level texture in its own cell, wrapped gutters around it;
  UVs outside 0..1 are clamped to the cell) and its ``lightmap_rect`` pointing at the patch's tile
  in the render atlases, edge-aligned (parameter 0 on the tile's outer texel edge, as the game
  samples);
* ``light``: the linear light ``CL`` the stored ``Cs``/``As`` encode against each patch's base
  texture reduced to 8x8, for ``modulate`` mode;
* ``source``: the stored ``(Cs, As)`` texels themselves, which ``ps2`` mode blends as the GS does,
  ``(Cd - Cs) As`` against the full-resolution base texture.

:func:`bake_level` bakes light maps the game's way (see :mod:`piste.formats.ssx.lightmap`):
lighting evaluated at each patch's 8x8 edge-aligned texel centres with terrain shadows, encoded
half-bright, ``As = max(CL)`` and ``Cs`` from :func:`piste.lighting.ps2.ps2_source` against the
patch's 8x8-reduced base texture, packed 256 patches a 128x128 page, transposed.

API
---
pbd_to_net(pbd, scale=0.01, tol=None, lightmap_rect=None, name=None) -> PatchNet (metres)
load_level(path, cell=64) -> SsxLevel
level_files(path) -> (ssh or None, light-map ssh or None)
bake_level(level, lights, shadows=True, jobs=1) -> BakedPages
write_baked(level, baked, out_pbd=None) -> (pbd path, _L.ssh path)
bake_file(path, lights=None, out=None, shadows=True, jobs=1) -> BakeReport
level_key(path) -> str                        content hash of the .pbd and its banks (build cache key)
bundle_arrays(path) -> {atlas, rects, source, base_texture}   what ``piste build`` stores for an SSX terrain
SSX_TRICKY_LOD = {"near": 30.0, "far": 150.0}     the ssx_tricky preset's switch distances (m)
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from piste.errors import ConfigError, FormatError, ValidationError
from piste.pipeline.cache import content_key
from piste.formats.ssx.lightmap import base_tiles, light_from_source, reduce_texture, tile_params
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import read_regular
from piste.formats.ssx.pbd import MAX_FILE_BYTES as MAX_PBD_BYTES
from piste.formats.ssx.pbd import (
    GAME_SCALE, NET_TO_UV, UV_TO_NET, Pbd, default_lightmap_tiles, read_pbd, weld_candidates, write_pbd,
)
from piste.formats.ssx.ssh import MAX_FILE_BYTES as MAX_SSH_BYTES
from piste.formats.ssx.ssh import (
    SshBank, extract_tiles, lightmap_bank, lightmap_pages, place_tiles, read_ssh, write_ssh,
)
from piste.lighting.lightmap import assemble_atlas, atlas_layout, encode_half_bright
from piste.lighting.lights import Lights, default_lights, light_terms, shade
from piste.lighting.ps2 import ps2_source
from piste.lighting.shadows import shadow_visibility
from piste.terrain.bezier import evaluate
from piste.terrain.net import PatchNet

__all__ = ["SsxLevel", "pbd_to_net", "load_level", "level_files", "bake_level", "BakedPages", "write_baked", "SSX_TRICKY_LOD",
           "texture_atlas", "level_key", "bundle_arrays", "bake_file", "BakeReport", "level_path"]

#: the ``ssx_tricky`` preset: the game's LOD switch distances (3000 / 15000 units) in metres
SSX_TRICKY_LOD = {"near": 30.0, "far": 150.0}
_WHITE = np.full((8, 8, 4), 255, np.uint8)


@dataclass
class SsxLevel:
    """A level ready to render (see the module docstring).

    Attributes
    ----------
    path : the .pbd;  pbd : Pbd;  textures, lightmaps : SshBank or None
    net : PatchNet (metres; uv into ``base_atlas``; lightmap_rect into ``light`` / ``source``)
    base_atlas : (H, W, 4) uint8 level textures, one cell each (+ a white cell for missing ones)
    reduced : (T, 8, 8, 3) uint8 each texture reduced to 8x8 (the game's Cs reference)
    light : (h, w, 3) float32 linear light for modulate mode (1.0 = full)
    source : (h, w, 4) uint8 stored Cs (RGB) and As (A, 128 = 1.0) for ps2 mode
    """

    path: Path
    pbd: Pbd
    net: PatchNet
    base_atlas: np.ndarray
    reduced: np.ndarray
    light: np.ndarray
    source: np.ndarray
    textures: SshBank | None = None
    lightmaps: SshBank | None = None
    info: dict = field(default_factory=dict)


def level_files(path: str | os.PathLike[str]) -> tuple[Path | None, Path | None]:
    """``(NAME.ssh, NAME_L.ssh)`` beside ``NAME.pbd`` (case-insensitive), each None if absent.
    The game's 8.3-style names may drop the stem's last character for the light maps
    (``elysium.pbd`` -> ``elysiu_L.ssh``), so that name is tried second."""
    path = Path(path)
    names = {p.name.lower(): p for p in path.parent.iterdir()} if path.parent.is_dir() else {}
    stem = path.stem.lower()
    light = names.get(f"{stem}_l.ssh") or (names.get(f"{stem[:-1]}_l.ssh") if len(stem) > 1 else None)
    return names.get(f"{stem}.ssh"), light


def texture_atlas(bank: SshBank | None, cell: int = 64, gutter: int = 8
                  ) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Every texture of ``bank`` resampled to ``cell x cell`` in a grid, with ``gutter`` wrapped
    texels around each, plus a final white cell.  Returns ``(atlas (H, W, 4) uint8, origins
    (T + 1, 2) texel (x, y) of each cell's inner corner, (W, H))``."""
    images = [im.rgba() for im in bank.images] if bank is not None else []
    cells = []
    for img in images + [_WHITE]:
        h, w = img.shape[:2]
        res = img[(np.arange(cell) * h // cell)][:, (np.arange(cell) * w // cell)]
        cells.append(np.pad(res, ((gutter, gutter), (gutter, gutter), (0, 0)), mode="wrap"))
    k = len(cells)
    cols = int(np.ceil(np.sqrt(k)))
    rows = int(np.ceil(k / cols))
    step = cell + 2 * gutter
    atlas = np.zeros((rows * step, cols * step, 4), np.uint8)
    origins = np.zeros((k, 2), np.int64)
    for i, c in enumerate(cells):
        y, x = (i // cols) * step, (i % cols) * step
        atlas[y:y + step, x:x + step] = c
        origins[i] = (x + gutter, y + gutter)
    return atlas, origins, (cols * step, rows * step)


def _atlas_uv(pbd: Pbd, origins: np.ndarray, size: tuple[int, int], cell: int, n_textures: int) -> np.ndarray:
    """Net corner UVs (PatchNet order) in the texture atlas, ``(n, 4, 2)`` float32."""
    ti = np.asarray(pbd.texture_index, dtype=np.int64)
    ti = np.where((ti >= 0) & (ti < n_textures), ti, n_textures)  # missing -> the white cell
    uv = np.clip(np.asarray(pbd.uv, dtype=np.float64), 0.0, 1.0)[:, NET_TO_UV]  # (n, 4, 2) net order
    o = origins[ti].astype(np.float64)[:, None, :]
    w, h = size
    out = np.empty_like(uv)
    out[..., 0] = (o[..., 0] + uv[..., 0] * cell) / w
    out[..., 1] = (o[..., 1] + uv[..., 1] * cell) / h
    return out.astype(np.float32)


def _render_tiles(tiles: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Tiles ``(n, 8, 8, C)`` into an atlas with a 1-texel gutter; returns ``(atlas, rects)`` with
    edge-aligned rects (parameter 0 / 1 on the tile's outer texel edges)."""
    lay = atlas_layout(n, 8, 1)
    atlas = assemble_atlas(tiles, lay)
    o = lay.origins().astype(np.float64)
    w, h = lay.width, lay.height
    rects = np.stack([o[:, 0] / w, o[:, 1] / h, (o[:, 0] + 8) / w, (o[:, 1] + 8) / h], 1).astype(np.float32)
    return atlas, rects


def level_light(pbd: Pbd, pages: np.ndarray | None, reduced: np.ndarray, pages_path: str | os.PathLike[str] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(light (h, w, 3) float32, source (h, w, 4) uint8, rects (n, 4))`` render atlases of a
    level's stored light-map pages (or unlit, ``Cs = 0, As = 128``, when ``pages`` is None).  A
    patch's tile outside the pages is refused naming the ``.pbd`` (``pbd.path``) and the bank
    (``pages_path``)."""
    n = len(pbd)
    if pages is None:
        tiles = np.zeros((n, 8, 8, 4), np.uint8)
        tiles[..., 3] = 128
    else:
        tiles = extract_tiles(pages, pbd.lightmap_rect, pbd.lightmap_page, pbd.path, pages_path)
    cd = base_tiles(reduced, pbd.texture_index, pbd.uv)
    cl = light_from_source(cd, tiles[..., :3], tiles[..., 3])
    light, rects = _render_tiles(cl, n)
    source, _ = _render_tiles(tiles, n)
    return light, source, rects


def pbd_to_net(pbd: Pbd, scale: float = GAME_SCALE, tol: float | None = None,
               lightmap_rect: np.ndarray | None = None,
               name: str | None = None) -> PatchNet:
    """The level's patches as a :class:`~piste.terrain.net.PatchNet` in metres.

    Parameters
    ----------
    pbd : Pbd
        The level (:func:`piste.formats.ssx.pbd.read_pbd`).
    scale : float
        Metres per game unit.
    tol : float or None
        Weld tolerance in metres.  Default: chosen from 1, 4 and 16 game units, the smallest that
        welds as many patch corners as 16 units does (the game's shared boundaries are near-equal,
        float32 at up to ~2e4 units, not bit-equal); should the net's C0 check still fail, the next
        larger one is tried.
    lightmap_rect : ndarray or None
        ``(n, 4)`` PatchNet-style ``(u0, v0, u1, v1)`` atlas rects (default: piste's own layout;
        see :func:`load_level` for the game's pages).
    name : str or None
        The net's name (default: the file's name).

    Raises
    ------
    FormatError
        A net that cannot be welded, naming the file and the ``patches`` field.
    """
    cp = np.asarray(pbd.control_points) * scale
    tols = [tol] if tol is not None else [t * scale for t in weld_candidates(pbd.control_points)]
    for k, t in enumerate(tols):
        try:
            # None: PatchNet lays out default rects (its field is typed np.ndarray, default None)
            return PatchNet(cp, uv=pbd.uv[:, UV_TO_NET], lightmap_rect=cast(np.ndarray, lightmap_rect), tol=t,
                            name=name or pbd.display_name)
        except ValidationError as exc:
            if k == len(tols) - 1 or "C0" not in str(exc):
                raise FormatError(pbd.path, str(exc), field="patches") from None
    raise AssertionError("unreachable: the last tolerance returns or raises")


def load_level(path: str | os.PathLike[str], cell: int = 64, tol: float | None = None) -> SsxLevel:
    """Read ``path`` (a .pbd) and the banks beside it; see the module docstring."""
    path = Path(path)
    pbd = read_pbd(path)
    ssh, lssh = level_files(path)
    textures = read_ssh(ssh) if ssh is not None else None
    lightmaps = read_ssh(lssh) if lssh is not None else None
    n_tex = len(textures) if textures is not None else 0
    reduced = np.stack([reduce_texture(im.rgba()) for im in (textures.images if textures else [])] + [_WHITE[..., :3]])
    base, origins, size = texture_atlas(textures, cell)
    pages = lightmap_pages(lightmaps, lssh) if lightmaps is not None else None
    light, source, rects = level_light(pbd, pages, reduced, lssh)
    net = pbd_to_net(pbd, tol=tol, lightmap_rect=rects)
    net.uv = _atlas_uv(pbd, origins, size, cell, n_tex)
    info = {"patches": len(pbd), "textures": n_tex, "lightmap_pages": 0 if pages is None else len(pages),
            "textures_file": ssh.name if ssh else None, "lightmaps_file": lssh.name if lssh else None}
    return SsxLevel(path, pbd, net, base, reduced, light, source, textures, lightmaps, info)


# ----------------------------------------------------------------------------- baking
@dataclass
class BakedPages:
    """A game-format bake: ``pages (P, 128, 128, 4) uint8`` (RGB = Cs, A = As), the new
    ``lightmap_rect (n, 4)`` and ``lightmap_page (n,)``, ``cl (n, 8, 8, 3) uint8`` the half-bright
    light, ``cd (n, 8, 8, 3) uint8`` the 8x8 base colour it was encoded against, ``stats``."""

    pages: np.ndarray
    lightmap_rect: np.ndarray
    lightmap_page: np.ndarray
    cl: np.ndarray
    cd: np.ndarray
    stats: dict


def _light_chunk(args: tuple[PatchNet, Lights, np.ndarray, np.ndarray, bool]) -> tuple[np.ndarray, dict[str, Any]]:
    net, lights, pos, nrm, shadows = args
    stats: dict = {}
    shadow = None
    if shadows and any(light.shadows for light in lights.direct):
        shadow = shadow_visibility(net, lights, pos, nrm, light_terms(lights, pos, nrm), stats=stats)
    return shade(lights, pos, nrm, shadow), stats


def bake_level(level: SsxLevel, lights: Lights, shadows: bool = True, jobs: int = 1, chunk: int = 256,
               method: str = "exact") -> BakedPages:
    """Bake ``level``'s light maps the game's way (module docstring).

    ``jobs`` > 1 runs chunks of ``chunk`` patches in a process pool (0 = every core).
    """
    net = level.net
    n = len(net)
    u, v = tile_params()
    pos, nrm = evaluate(net.control_points, u, v)  # (n, 64, 3)
    pos = pos.reshape(-1, 3)
    nrm = nrm.reshape(-1, 3)
    per = chunk * 64
    work = [(net, lights, pos[i:i + per], nrm[i:i + per], shadows) for i in range(0, len(pos), per)]
    jobs = (os.cpu_count() or 1) if not jobs or jobs <= 0 else int(jobs)
    t0 = time.perf_counter()
    if jobs > 1 and len(work) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(jobs, len(work))) as ex:
            results = list(ex.map(_light_chunk, work))
    else:
        results = [_light_chunk(w) for w in work]
    colors = np.concatenate([r[0] for r in results]).reshape(n, 8, 8, 3)
    stats = {"seconds_lighting": time.perf_counter() - t0}
    for _, st in results:
        for k, val in st.items():
            stats[k] = stats.get(k, 0) + int(val)
    cl = encode_half_bright(colors)
    cd = base_tiles(level.reduced, level.pbd.texture_index, level.pbd.uv)
    cs, as_ = ps2_source(cd, cl, method)
    tiles = np.concatenate([cs, as_[..., None]], axis=-1).astype(np.uint8)
    rect, page = default_lightmap_tiles(n)
    pages = place_tiles(tiles, rect, page, int(page.max()) + 1)
    return BakedPages(pages, rect, page, cl, cd, stats)


def write_baked(level: SsxLevel, baked: BakedPages, out_pbd: str | os.PathLike[str] | None = None) -> tuple[Path, Path]:
    """Write the baked pages as ``NAME_L.ssh`` beside ``out_pbd`` (default: the level's own .pbd,
    rewritten) and the .pbd with every patch's light-map rect and page updated, every other byte
    as read (a new name also gets a byte-for-byte copy of the level's ``.ssh`` as ``NAME.ssh``);
    each atomic.  The same level and lights give the same bytes."""
    out = Path(out_pbd) if out_pbd is not None else level.path
    if out.suffix.lower() != ".pbd":
        raise ConfigError(f"{out}: the output level must be a .pbd")
    level.pbd.lightmap_rect = baked.lightmap_rect.copy()
    level.pbd.lightmap_page = baked.lightmap_page.astype(np.int16)
    lpath = out.with_name(f"{out.stem}_L.ssh")
    write_ssh(lightmap_bank(baked.pages), lpath)
    src = level.info.get("textures_file")
    if src and out.resolve() != level.path.resolve():  # the new level's own textures: the source's bytes
        write_bytes_atomic(out.with_name(f"{out.stem}.ssh"),
                           read_regular(level.path.with_name(src), MAX_SSH_BYTES, what="texture bank"))
    write_pbd(level.pbd, out)
    return out, lpath


@dataclass
class BakeReport:
    """What :func:`bake_file` wrote: the ``.pbd`` and ``_L.ssh`` paths, counts and the time taken."""

    pbd: Path
    lightmaps: Path
    patches: int
    pages: int
    rays: int
    rays_occluded: int
    seconds: float

    def summary(self) -> str:
        return (f"baked {self.patches} patches into {self.pages} light-map page(s) ({self.rays:,} shadow rays, "
                f"{self.rays_occluded:,} occluded) in {self.seconds:.2f} s: {self.lightmaps}, {self.pbd}")


def level_path(path: str | os.PathLike[str]) -> Path:
    """``path`` as an SSX level path (ConfigError unless it names a ``.pbd``)."""
    p = Path(path)
    if p.suffix.lower() != ".pbd":
        raise ConfigError(f"{path}: expected an SSX Tricky level (.pbd)")
    return p


def bake_file(path: str | os.PathLike[str], lights: Lights | None = None, out: str | os.PathLike[str] | None = None, shadows: bool = True, jobs: int = 1) -> BakeReport:
    """``piste ssx bake`` / ``piste bake LEVEL.pbd --format ssx-tricky``: bake ``NAME_L.ssh`` the
    game's way with ``lights`` (default: piste's) and write it with the level (:func:`write_baked`)."""
    t0 = time.perf_counter()
    level = load_level(level_path(path))
    baked = bake_level(level, lights if lights is not None else default_lights(), shadows=shadows, jobs=jobs)
    pbd, lssh = write_baked(level, baked, out)
    st = baked.stats
    return BakeReport(pbd, lssh, len(level.pbd), len(baked.pages), int(st.get("rays", 0)),
                      int(st.get("rays_occluded", 0)), time.perf_counter() - t0)


# ----------------------------------------------------------------------------- scene builds
def level_key(path: str | os.PathLike[str]) -> str:
    """Content hash of ``path`` and the ``.ssh`` / ``_L.ssh`` beside it (a build-cache key part)."""
    path = Path(path)
    parts: list[str | bytes] = []
    for p in (path, *level_files(path)):  # regular files only (a pipe or device is refused, never read)
        parts += ["-"] if p is None else [p.name, read_regular(p, MAX_PBD_BYTES, what="level file")]
    return content_key("ssx-level/2", *parts)


def bundle_arrays(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """What a scene build stores for an SSX terrain (``[terrain] ssx_pbd = ...``): the level's own
    light map as the bundle's linear ``atlas (h, w, 3) float32`` with its ``rects (n, 4)``, the
    stored texels as ``source (h, w, 4) uint8`` (Cs, As: ps2 mode) and the level textures as
    ``base_texture (H, W, 4) uint8`` (the net's UVs point into it)."""
    level = load_level(path)
    return {"atlas": level.light.astype(np.float32), "rects": level.net.lightmap_rect.astype(np.float32),
            "base_texture": level.base_atlas, "source": level.source}
