"""The SSX modding community's Multitool project: ``Patches.json`` with ``Textures/`` and
``Lightmaps/`` beside it (read by Blender's bxtools and Unity's IceSaw).

Facts (``/work/shared/SSX-FORMATS.md``; the Multitool's own conventions checked in SSX-Library's
``TrickyLevelInterface.cs`` and ``OldShapeHandler.cs``, facts only): per patch ``PatchName``,
``LightMapPoint[4]``, ``UVPoints[4][2]``, ``Points[16][3]`` (raw Bézier points, row-major, game
units), ``SurfaceType``, ``TrickOnlyPatch``, ``TexturePath`` and ``LightmapID``.  piste writes
``{"Patches": [...]}`` and reads that or a bare list.

The Multitool's conventions, which piste follows both ways:

* **Textures** are exported **brightened**: RGB -> ``clamp(2c - 1, 0, 255)`` always; a palette
  image whose palette alpha never exceeds 128 gets its alpha doubled (capped at 255), any other
  alpha is left as stored.  ``TexturePath`` is the texture's 4-character bank name + ``.png``.
  On import textures are numbered **by first appearance** in ``Patches.json`` (the number in a
  file name is ignored; only referenced files are read) and stored darkened, RGB -> ``(c + 1) //
  2``, as 8-bit palette images named ``0000``, ``0001``, ...  Alpha is halved too; piste rounds
  up, ``(a + 1) // 2``, the exact inverse of the export (the Multitool's ``a // 2`` turns an
  exported 255 into 127, not the stored 128).
* **Light maps** are exported brightened the same way, RGB -> ``clamp(2c - 1, 0, 255)``, alpha
  **as stored** (``As``, 128 = 1.0, up to 255); on import every ``Lightmaps/*.png`` is a page, in
  file-name order (page ``i`` is the ``i``-th name), darkened RGB -> ``(c + 1) // 2``, alpha as
  stored.  The two are exact inverses for stored RGB <= 128 (the game's ``Cs`` are: ``Cs <= Cd``,
  and the GS's ``Cd`` is the half-bright texture); a stored value above 128 comes back as 128.

What a project holds, and nothing else, becomes the level (:meth:`Project.to_level`):

* a project written by piste also holds the level it was written from (``PisteLevel.pbd``, and
  in ``PisteLevel.json`` the order of its texture bank): when ``Patches.json`` still has that
  level's patch count, the new ``.pbd`` is that level with the project's per-patch fields written
  into it (patches whose points did not change keep their stored floats), so instances, lights,
  splines, models and every other section come back as they were; texture numbering starts from
  the recorded bank order (which the level's materials refer to), then first appearance;
* otherwise the ``.pbd`` holds the project's patches and the minimal default for every other
  section (empty, count 0; :func:`piste.formats.ssx.synth.pbd_bytes`).  The Multitool's
  ``Instances.json``, ``Lights.json``, ``Splines.json``, ``Models.json``, ... are not read by
  piste: each one present is named in :attr:`Project.notes` (what the new level lacks);
* no ``Textures/`` folder: no texture bank; no ``Lightmaps/`` folder: no light-map bank.

Reading and writing are deterministic: the same input gives the same bytes.

API
---
write_project(folder, pbd, textures=None, lightmaps=None)       atomic per file
read_project(folder) -> Project
Project.to_level() -> (Pbd, SshBank textures or None, SshBank light maps or None)
brighten(rgb) / darken(rgb)                                      the Multitool's RGB conventions
"""

from __future__ import annotations

import io
import json
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from piste.errors import FormatError, PisteError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import anchor, loads_json, read_regular
from piste.formats.ssx.pbd import COUNT_NAMES, MAX_FILE_BYTES as MAX_PBD_BYTES, Pbd, parse_pbd, records_from_arrays
from piste.formats.ssx.ssh import INDEXED, PAGE_SIZE, SshBank, SshImage, half_bright, lightmap_bank
from piste.formats.ssx.synth import pbd_bytes

__all__ = ["write_project", "read_project", "Project", "brighten", "darken", "export_texture", "export_lightmap",
           "SOURCE_PBD", "SOURCE_JSON", "OTHER_JSON"]

#: most patches / images a project may hold (hostile files are refused before allocating)
MAX_PATCHES = 1_000_000
#: largest Patches.json read (about 2 KB a patch)
MAX_JSON_BYTES = 1 << 31
#: largest PNG read
MAX_PNG_BYTES = 256 << 20
#: texture numbers and LightmapIDs are int16 in the .pbd; light-map pages (64 KiB each) at most this many
MAX_INDEX = 32767
MAX_LIGHTMAP_PAGES = 4096
_NAME = re.compile(r"^[A-Za-z0-9_.\- ]+\.png$")
#: piste's record of the level a project was written from
SOURCE_PBD = "PisteLevel.pbd"
SOURCE_JSON = "PisteLevel.json"
#: the Multitool's other files, which piste does not read (named in Project.notes when present)
OTHER_JSON = ("Instances.json", "ParticleInstances.json", "Materials.json", "Lights.json", "Splines.json",
              "Models.json", "ParticleModels.json", "Cameras.json", "AIP.json", "SOP.json", "SSFLogic.json")


# ----------------------------------------------------------------------------- the conventions
def brighten(rgb) -> np.ndarray:
    """The Multitool's export brightening ``clamp(2c - 1, 0, 255)``: ``(...) uint8`` -> same shape."""
    return np.clip(np.asarray(rgb).astype(np.int16) * 2 - 1, 0, 255).astype(np.uint8)


def darken(rgb) -> np.ndarray:
    """The Multitool's import darkening ``(c + 1) // 2``: ``(...) uint8`` -> same shape."""
    return ((np.asarray(rgb).astype(np.uint16) + 1) // 2).astype(np.uint8)


def export_texture(im: SshImage) -> np.ndarray:
    """A texture as the Multitool exports it, ``(h, w, 4) uint8``: RGB brightened always; a palette
    image's alpha doubled (capped at 255) when no palette entry's alpha exceeds 128."""
    if im.kind in INDEXED:
        pal = np.asarray(im.palette, np.uint8).copy()
        if int(pal[:, 3].max(initial=0)) <= 128:
            pal[:, 3] = np.minimum(pal[:, 3].astype(np.uint16) * 2, 255).astype(np.uint8)
        pal[:, :3] = brighten(pal[:, :3])
        return pal[np.asarray(im.pixels)]
    out = np.asarray(im.stored_rgba(), np.uint8).copy()
    out[..., :3] = brighten(out[..., :3])
    return out


def export_lightmap(page) -> np.ndarray:
    """A stored light-map page ``(128, 128, 4) uint8`` as the Multitool exports it: RGB brightened,
    alpha as stored."""
    out = np.asarray(page, np.uint8).copy()
    out[..., :3] = brighten(out[..., :3])
    return out


def _png_bytes(img: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img), "RGBA").save(buf, format="PNG")
    return buf.getvalue()


def _bank_names(bank: SshBank | None) -> list | None:
    """File names (``NAME.png``) of a bank's images: their 4-character bank names as the Multitool
    writes them when those are unique plain names, else ``NNNN.png`` by position."""
    if bank is None:
        return None
    names = [f"{im.name}.png" for im in bank.images]
    if len(set(n.lower() for n in names)) == len(names) and all(_NAME.match(n) for n in names):
        return names
    return [f"{i:04d}.png" for i in range(len(bank))]


# ----------------------------------------------------------------------------- writing
def write_project(folder, pbd: Pbd, textures: SshBank | None = None, lightmaps: SshBank | None = None) -> Path:
    """Write ``Patches.json``, ``Textures/NAME.png`` and ``Lightmaps/NNNN.png`` into ``folder`` the
    Multitool's way (module docstring), and piste's record of the level (``PisteLevel.pbd``,
    ``PisteLevel.json``).  Returns the path of ``Patches.json``."""
    folder = Path(folder)
    n = len(pbd)
    cp = np.asarray(pbd.control_points, dtype=np.float64).reshape(n, 16, 3)
    tex_names = _bank_names(textures)
    patches = []
    for k in range(n):
        t = int(pbd.texture_index[k])
        if tex_names is not None and 0 <= t < len(tex_names):
            tp = tex_names[t]
        else:
            tp = f"{t:04d}.png" if t >= 0 else ""
        patches.append({
            "PatchName": f"Patch {k}",
            "LightMapPoint": [float(x) for x in pbd.lightmap_rect[k]],
            "UVPoints": [[float(a), float(b)] for a, b in pbd.uv[k]],
            "Points": [[float(a), float(b), float(c)] for a, b, c in cp[k]],
            "SurfaceType": int(pbd.surface_type[k]),
            "TrickOnlyPatch": bool(pbd.trick_only[k]),
            "TexturePath": tp,
            "LightmapID": int(pbd.lightmap_page[k]),
        })
    write_bytes_atomic(folder / "Patches.json", json.dumps({"Patches": patches}, indent=1).encode())
    if textures is not None:
        for name, im in zip(tex_names, textures.images):
            write_bytes_atomic(folder / "Textures" / name, _png_bytes(export_texture(im)))
    if lightmaps is not None:
        for i, im in enumerate(lightmaps.images):
            write_bytes_atomic(folder / "Lightmaps" / f"{i:04d}.png", _png_bytes(export_lightmap(im.stored_rgba())))
    write_bytes_atomic(folder / SOURCE_PBD, pbd.to_bytes())
    record = {"piste": "ssx-level/1", "level": SOURCE_PBD, "patches": n,
              "textures": tex_names if tex_names is not None else []}
    write_bytes_atomic(folder / SOURCE_JSON, json.dumps(record, indent=1).encode())
    return folder / "Patches.json"


# ----------------------------------------------------------------------------- reading
@dataclass
class Project:
    """A Multitool project as read: per-patch arrays (game units, as :class:`Pbd`), ``names``,
    ``texture_files`` (file name of texture ``i``), ``textures`` ``{index: (h, w, 4) uint8}`` and
    ``lightmaps`` ``{page: (128, 128, 4) uint8}`` as the PNGs hold them (brightened), ``source``
    the level a piste-written project records (or None), ``notes`` what the new level will lack."""

    path: Path
    control_points: np.ndarray
    uv: np.ndarray
    lightmap_rect: np.ndarray
    lightmap_page: np.ndarray
    texture_index: np.ndarray
    surface_type: np.ndarray
    trick_only: np.ndarray
    names: list = field(default_factory=list)
    textures: dict = field(default_factory=dict)
    lightmaps: dict = field(default_factory=dict)
    texture_files: list = field(default_factory=list)
    has_textures: bool = False
    has_lightmaps: bool = False
    source: Pbd | None = None
    notes: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.control_points)

    def to_level(self) -> tuple[Pbd, SshBank | None, SshBank | None]:
        """The level the project holds: ``(Pbd, textures or None, light maps or None)`` (see the
        module docstring: the recorded source level's sections when the patch count matches, else
        the minimal default; only the banks the project has folders for)."""
        n = len(self)
        textures = None
        if self.has_textures:
            textures = SshBank([_indexed(f"{i:04d}", self.textures[i]) for i in range(len(self.texture_files))])
        lightmaps = None
        if self.has_lightmaps:
            pages = np.zeros((len(self.lightmaps), PAGE_SIZE, PAGE_SIZE, 4), np.uint8)
            for i, img in self.lightmaps.items():
                pages[i, ..., :3] = darken(img[..., :3])
                pages[i, ..., 3] = img[..., 3]
            lightmaps = lightmap_bank(pages)
        n_tex = len(textures) if textures is not None else (len(self.texture_files) if self.texture_files else 0)
        if self.source is not None and len(self.source) == n:
            pbd = parse_pbd(self.source.raw, self.path)
            pbd.control_points = np.asarray(self.control_points, np.float64).copy()
            pbd.uv = self.uv.copy()
            pbd.lightmap_rect = self.lightmap_rect.copy()
            pbd.lightmap_page = self.lightmap_page.copy()
            pbd.texture_index = self.texture_index.copy()
            pbd.surface_type = self.surface_type.copy()
            pbd.trick_only = self.trick_only.copy()
            data = bytearray(pbd.to_bytes())
            if textures is not None:  # the header's texture count follows the bank written beside it
                struct.pack_into("<I", data, 4 + 4 * COUNT_NAMES.index("textures"), len(textures))
            return parse_pbd(bytes(data), self.path), textures, lightmaps
        rec = records_from_arrays(self.control_points, self.uv, self.lightmap_rect, self.lightmap_page,
                                  self.texture_index, self.surface_type, self.trick_only)
        platform = self.source.platform if self.source is not None else 1
        return parse_pbd(pbd_bytes(rec, n_tex, platform), self.path), textures, lightmaps


def _indexed(name: str, rgba: np.ndarray) -> SshImage:
    """A texture PNG ``(h, w, 4)`` stored the Multitool's way: darkened (RGB ``(c + 1) // 2``,
    alpha ``(a + 1) // 2``), an 8-bit palette image (exact for <= 256 colours; more are quantised),
    palette entries in order of their colour value, an empty long name (as the game's level banks)."""
    h, w = rgba.shape[:2]
    stored = half_bright(rgba)
    flat = stored.reshape(-1, 4)
    colours, idx = np.unique(flat, axis=0, return_inverse=True)
    if len(colours) > 256:
        from PIL import Image

        q = Image.fromarray(stored, "RGBA").quantize(256, method=Image.Quantize.FASTOCTREE)
        pal = np.asarray(q.getpalette("RGBA"), np.uint8).reshape(-1, 4)[:256]
        return SshImage(name, 2, np.asarray(q, np.uint8), pal.copy(), long_name="")
    return SshImage(name, 2, idx.reshape(h, w).astype(np.uint8), colours.astype(np.uint8), long_name="")


def _read_png(path: Path) -> np.ndarray:
    """An image file as ``(h, w, 4) uint8`` RGBA (regular files only, through safe_io)."""
    from PIL import Image

    data = read_regular(path, MAX_PNG_BYTES, owner=path, what="image")
    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.width * im.height > 4096 * 4096:
                raise FormatError(path, f"image of {im.width}x{im.height} is too large")
            return np.asarray(im.convert("RGBA"))
    except PisteError:
        raise
    except Exception as exc:
        raise FormatError(path, f"not a readable PNG ({exc})") from None


def _list_pngs(folder: Path) -> list:
    """The ``*.png`` files of ``folder`` in file-name order (the order the Multitool numbers light-map
    pages in)."""
    return sorted((p for p in folder.iterdir() if p.suffix.lower() == ".png"), key=lambda p: p.name)


def _read_source(folder: Path):
    """``(Pbd, texture file names)`` recorded by piste's :func:`write_project`, or ``(None, [])``."""
    jpath = folder / SOURCE_JSON
    if not jpath.exists():
        return None, []
    doc = loads_json(read_regular(jpath, 64 << 20, what="project record"), jpath)
    if not isinstance(doc, dict) or doc.get("level") != SOURCE_PBD:
        raise FormatError(jpath, f"expected {{\"level\": \"{SOURCE_PBD}\", ...}}", field="level")
    names = doc.get("textures", [])
    if not isinstance(names, list) or len(names) > MAX_INDEX + 1 or not all(
            isinstance(t, str) and _NAME.match(t) for t in names):
        raise FormatError(jpath, "expected a list of plain 'NAME.png' texture file names", field="textures")
    ppath = folder / SOURCE_PBD
    return parse_pbd(read_regular(ppath, MAX_PBD_BYTES, what="level file"), ppath), list(names)


def read_project(folder) -> Project:
    """Read a Multitool project folder (or its ``Patches.json``); see the module docstring."""
    folder = Path(folder)
    jpath = folder if folder.suffix.lower() == ".json" else folder / "Patches.json"
    # the user's folder, as a confinement root (piste.formats.safe_io): every file below it is opened
    # without following links (a linked Textures/ is refused) and fstat-ed first (a FIFO never blocks)
    folder = Path(anchor(jpath.parent))
    jpath = folder / jpath.name
    if not jpath.exists():
        raise FormatError(jpath, "no such file")
    doc = loads_json(read_regular(jpath, MAX_JSON_BYTES), jpath)
    items = doc.get("Patches") if isinstance(doc, dict) else doc
    if not isinstance(items, list):
        raise FormatError(jpath, "expected a list of patches (or {\"Patches\": [...]})", field="Patches")
    n = len(items)
    if n == 0 or n > MAX_PATCHES:
        raise FormatError(jpath, f"expected 1..{MAX_PATCHES} patches, got {n}", field="Patches")
    source, recorded = _read_source(folder)
    cp = np.zeros((n, 16, 3))
    uv = np.zeros((n, 4, 2), np.float32)
    rect = np.zeros((n, 4), np.float32)
    page = np.zeros(n, np.int16)
    tex = np.zeros(n, np.int16)
    surf = np.zeros(n, np.uint32)
    trick = np.zeros(n, bool)
    names = []
    files = list(recorded)  # texture i's file name: the recorded bank order, then first appearance
    number = {f: i for i, f in enumerate(files)}
    first_use: dict = {}
    for k, p in enumerate(items):
        where = f"patch {k}"
        try:
            cp[k] = np.asarray(p["Points"], dtype=np.float64).reshape(16, 3)
            uv[k] = np.asarray(p["UVPoints"], dtype=np.float32).reshape(4, 2)
            rect[k] = np.asarray(p["LightMapPoint"], dtype=np.float32).reshape(4)
            lm, st = int(p.get("LightmapID", 0)), int(p.get("SurfaceType", 1))
            trick[k] = bool(p.get("TrickOnlyPatch", False))
            tp = p.get("TexturePath", "")
            if not isinstance(tp, str):
                raise TypeError(f"TexturePath must be a string, got {type(tp).__name__}")
        except KeyError as exc:
            raise FormatError(jpath, f"{where}: missing key", field=str(exc.args[0])) from None
        except (TypeError, ValueError, AttributeError, OverflowError) as exc:
            raise FormatError(jpath, f"{where}: wrong shape or type ({exc})", field="Points/UVPoints/LightMapPoint") from None
        if not 0 <= lm < MAX_LIGHTMAP_PAGES:
            raise FormatError(jpath, f"{where}: LightmapID {lm} is not a page 0..{MAX_LIGHTMAP_PAGES - 1}",
                              field="LightmapID")
        if not 0 <= st < 2**32:
            raise FormatError(jpath, f"{where}: SurfaceType {st} is not a 32-bit unsigned number", field="SurfaceType")
        page[k], surf[k] = lm, st
        if not np.isfinite(cp[k]).all():
            raise FormatError(jpath, f"{where}: non-finite control point", field="Points")
        if tp == "":
            tex[k] = -1  # no texture
        else:
            if not _NAME.match(tp) or "/" in tp or "\\" in tp:
                raise FormatError(jpath, f"{where}: TexturePath {tp!r} must be a plain 'NAME.png' file name in "
                                         "Textures/", field="TexturePath")
            if tp not in number:
                if len(files) > MAX_INDEX:
                    raise FormatError(jpath, f"{where}: more than {MAX_INDEX + 1} textures", field="TexturePath")
                number[tp] = len(files)
                files.append(tp)
            first_use.setdefault(tp, k)
            tex[k] = number[tp]
        names.append(str(p.get("PatchName", f"Patch {k}")))
    proj = Project(jpath, cp.reshape(n, 4, 4, 3), uv, rect, page, tex, surf, trick, names, texture_files=files,
                   source=source)
    tdir = folder / "Textures"
    if tdir.is_dir():
        proj.has_textures = True
        for i, name in enumerate(files):
            f = tdir / name
            if not f.exists() and not f.is_symlink():
                k = first_use.get(name)
                why = f"patch {k}: TexturePath {name!r}" if k is not None else f"texture {name!r} ({SOURCE_JSON})"
                raise FormatError(jpath, f"{why}: Textures/{name} does not exist", field="TexturePath")
            proj.textures[i] = _read_png(f)
    ldir = folder / "Lightmaps"
    if ldir.is_dir():
        proj.has_lightmaps = True
        pngs = _list_pngs(ldir)
        if len(pngs) > MAX_LIGHTMAP_PAGES:
            raise FormatError(ldir, f"{len(pngs)} light-map pages: more than the limit of {MAX_LIGHTMAP_PAGES}")
        for i, f in enumerate(pngs):
            img = _read_png(f)
            if img.shape[:2] != (PAGE_SIZE, PAGE_SIZE):
                raise FormatError(f, f"a light-map page must be 128x128, got {img.shape[1]}x{img.shape[0]}")
            proj.lightmaps[i] = img
        bad = page >= len(pngs)
        if bad.any():
            k = int(np.argmax(bad))
            raise FormatError(jpath, f"patch {k}: LightmapID {int(page[k])} but Lightmaps/ holds {len(pngs)} page(s)",
                              field="LightmapID")
    if source is not None and len(source) != n:
        kept = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in source.counts.items()
                         if v and k not in ("patches", "textures", "lightmap_size"))
        proj.notes.append(f"{SOURCE_PBD} holds {len(source)} patches, Patches.json {n}: the level's other sections "
                          f"({kept or 'none'}) hold absolute offsets piste does not relocate, so the new level has "
                          "the minimal default (empty) for them")
    for other in OTHER_JSON:
        if (folder / other).exists():
            if source is not None and len(source) == n:
                proj.notes.append(f"{other}: not read by piste (the level's sections come from {SOURCE_PBD})")
            else:
                proj.notes.append(f"{other}: not read by piste: the new level has none of what it holds")
    return proj
