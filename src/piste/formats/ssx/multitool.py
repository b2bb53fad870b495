"""The SSX modding community's Multitool project: ``Patches.json`` with ``Textures/`` and
``Lightmaps/`` beside it (read by Blender's bxtools and Unity's IceSaw).

Facts (``/work/shared/SSX-FORMATS.md``): per patch ``PatchName``, ``LightMapPoint[4]``,
``UVPoints[4][2]``, ``Points[16][3]`` (raw Bézier points, row-major, game units), ``SurfaceType``,
``TrickOnlyPatch``, ``TexturePath`` (``"NNNN.png"``) and ``LightmapID``.  piste writes
``{"Patches": [...]}`` and reads that or a bare list.  Textures are written as display RGBA PNGs
(the half-bright storage undone, :meth:`SshImage.rgba`); light-map pages as the stored ``(Cs,
As)`` RGBA (never brightened, 128 = 1.0).  Reading a project back stores each texture half-bright
again (``(c + 1) // 2``) as an 8-bit palette (exact for a level texture written by piste: at most
256 colours, brightened from half-bright).

API
---
write_project(folder, pbd, textures=None, lightmaps=None)       atomic per file
read_project(folder) -> Project
Project.to_level(seed=0) -> (Pbd, SshBank textures, SshBank light maps)
"""

from __future__ import annotations

import io
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from piste.errors import FormatError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import anchor, loads_json, open_file, read_regular
from piste.formats.ssx.pbd import Pbd, parse_pbd, records_from_arrays
from piste.formats.ssx.ssh import PAGE_SIZE, SshBank, SshImage, half_bright, lightmap_bank
from piste.formats.ssx.synth import pbd_bytes

__all__ = ["write_project", "read_project", "Project"]

#: most patches / images a project may hold (hostile files are refused before allocating)
MAX_PATCHES = 1_000_000
#: largest Patches.json read (about 2 KB a patch)
MAX_JSON_BYTES = 1 << 31
#: texture numbers and LightmapIDs are int16 in the .pbd; light-map pages (64 KiB each) at most this many
MAX_INDEX = 32767
MAX_LIGHTMAP_PAGES = 4096
_NAME = re.compile(r"^[A-Za-z0-9_.\- ]+\.png$")


def _png_bytes(img: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img)).save(buf, format="PNG")
    return buf.getvalue()


def write_project(folder, pbd: Pbd, textures: SshBank | None = None, lightmaps: SshBank | None = None) -> Path:
    """Write ``Patches.json`` (+ ``Textures/NNNN.png``, ``Lightmaps/NNNN.png``) into ``folder``."""
    folder = Path(folder)
    n = len(pbd)
    cp = np.asarray(pbd.control_points, dtype=np.float64).reshape(n, 16, 3)
    patches = []
    for k in range(n):
        patches.append({
            "PatchName": f"Patch {k}",
            "LightMapPoint": [float(x) for x in pbd.lightmap_rect[k]],
            "UVPoints": [[float(a), float(b)] for a, b in pbd.uv[k]],
            "Points": [[float(a), float(b), float(c)] for a, b, c in cp[k]],
            "SurfaceType": int(pbd.surface_type[k]),
            "TrickOnlyPatch": bool(pbd.trick_only[k]),
            "TexturePath": f"{int(pbd.texture_index[k]):04d}.png",
            "LightmapID": int(pbd.lightmap_page[k]),
        })
    write_bytes_atomic(folder / "Patches.json", json.dumps({"Patches": patches}, indent=1).encode())
    if textures is not None:
        for i, im in enumerate(textures.images):
            write_bytes_atomic(folder / "Textures" / f"{i:04d}.png", _png_bytes(im.rgba()))
    if lightmaps is not None:
        for i, im in enumerate(lightmaps.images):
            write_bytes_atomic(folder / "Lightmaps" / f"{i:04d}.png", _png_bytes(im.stored_rgba()))
    return folder / "Patches.json"


@dataclass
class Project:
    """A Multitool project as read: per-patch arrays (game units, as :class:`Pbd`), ``names``,
    ``textures`` ``{index: (h, w, 4) uint8}`` (display alpha) and ``lightmaps`` ``{index: (128,
    128, 4) uint8}`` (stored alpha)."""

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

    def to_level(self, seed: int = 0) -> tuple[Pbd, SshBank, SshBank]:
        """A new level from the project (the .pbd laid out by piste's encoder)."""
        rec = records_from_arrays(self.control_points, self.uv, self.lightmap_rect, self.lightmap_page,
                                  self.texture_index, self.surface_type, self.trick_only)
        n_tex = max(self.textures) + 1 if self.textures else 0
        pbd = parse_pbd(pbd_bytes(rec, n_tex, seed=seed), self.path)
        images = []
        for i in range(n_tex):
            img = self.textures.get(i, np.full((8, 8, 4), 255, np.uint8))
            images.append(_indexed(f"{i:04d}", img))
        n_lm = max(self.lightmaps) + 1 if self.lightmaps else 0
        pages = np.zeros((n_lm, PAGE_SIZE, PAGE_SIZE, 4), np.uint8)
        for i, img in self.lightmaps.items():
            pages[i] = img
        return pbd, SshBank(images), lightmap_bank(pages)


def _indexed(name: str, rgba: np.ndarray) -> SshImage:
    """An 8-bit indexed image stored half-bright (exact for <= 256 colours)."""
    h, w = rgba.shape[:2]
    stored = half_bright(rgba)
    flat = stored.reshape(-1, 4)
    colours, idx = np.unique(flat, axis=0, return_inverse=True)
    if len(colours) > 256:
        from PIL import Image

        q = Image.fromarray(stored, "RGBA").quantize(256, method=Image.Quantize.FASTOCTREE)
        pal = np.asarray(q.getpalette("RGBA"), np.uint8).reshape(-1, 4)[:256]
        return SshImage(name, 2, np.asarray(q, np.uint8), pal.copy())
    return SshImage(name, 2, idx.reshape(h, w).astype(np.uint8), colours.astype(np.uint8))


def _read_png(path: Path, folder: Path) -> np.ndarray:
    from PIL import Image

    try:
        if path.parent != folder:
            raise FormatError(path, "image path leaves the project's folder")
        # opened without following links (a linked Textures/ is refused) and fstat-ed before a read
        # (a FIFO at Textures/0000.png is refused, never opened for reading): piste.formats.safe_io
        with open_file(path, 64 << 20, what="image") as fh, Image.open(fh) as im:
            if im.width * im.height > 4096 * 4096:
                raise FormatError(path, f"image of {im.width}x{im.height} is too large")
            return np.asarray(im.convert("RGBA"))
    except FormatError:
        raise
    except Exception as exc:
        raise FormatError(path, f"not a readable PNG ({exc})") from None


def read_project(folder) -> Project:
    """Read a Multitool project folder (or its ``Patches.json``)."""
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
    cp = np.zeros((n, 16, 3))
    uv = np.zeros((n, 4, 2), np.float32)
    rect = np.zeros((n, 4), np.float32)
    page = np.zeros(n, np.int16)
    tex = np.zeros(n, np.int16)
    surf = np.zeros(n, np.uint32)
    trick = np.zeros(n, bool)
    names = []
    tex_files: dict = {}
    for k, p in enumerate(items):
        where = f"patch {k}"
        try:
            cp[k] = np.asarray(p["Points"], dtype=np.float64).reshape(16, 3)
            uv[k] = np.asarray(p["UVPoints"], dtype=np.float32).reshape(4, 2)
            rect[k] = np.asarray(p["LightMapPoint"], dtype=np.float32).reshape(4)
            lm, st = int(p.get("LightmapID", 0)), int(p.get("SurfaceType", 1))
            trick[k] = bool(p.get("TrickOnlyPatch", False))
            tp = str(p.get("TexturePath", "0000.png"))
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
        if not _NAME.match(tp) or "/" in tp or "\\" in tp:
            raise FormatError(jpath, f"{where}: TexturePath {tp!r} must be a plain 'NNNN.png' name in Textures/",
                              field="TexturePath")
        m = re.match(r"^(\d+)\.png$", tp)
        t = int(m.group(1)) if m else tex_files.setdefault(tp, len(tex_files))
        if t > MAX_INDEX:
            raise FormatError(jpath, f"{where}: TexturePath {tp!r} is not a texture 0..{MAX_INDEX}", field="TexturePath")
        tex[k] = t
        names.append(str(p.get("PatchName", f"Patch {k}")))
    textures = {}
    tdir = folder / "Textures"
    if tdir.is_dir():
        for f in sorted(tdir.glob("*.png")):
            if re.match(r"^\d+\.png$", f.name):
                if int(f.stem) > MAX_INDEX:
                    raise FormatError(f, f"a texture is numbered 0..{MAX_INDEX}")
                textures[int(f.stem)] = _read_png(f, tdir)
            elif f.name in tex_files:
                textures[tex_files[f.name]] = _read_png(f, tdir)
    lightmaps = {}
    ldir = folder / "Lightmaps"
    if ldir.is_dir():
        for f in sorted(ldir.glob("*.png")):
            if re.match(r"^\d+\.png$", f.name):
                if int(f.stem) >= MAX_LIGHTMAP_PAGES:
                    raise FormatError(f, f"a light-map page is numbered 0..{MAX_LIGHTMAP_PAGES - 1}")
                img = _read_png(f, ldir)
                if img.shape[:2] != (PAGE_SIZE, PAGE_SIZE):
                    raise FormatError(f, f"a light-map page must be 128x128, got {img.shape[1]}x{img.shape[0]}")
                lightmaps[int(f.stem)] = img
    return Project(jpath, cp.reshape(n, 4, 4, 3), uv, rect, page, tex, surf, trick, names, textures, lightmaps)
