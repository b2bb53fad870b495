"""The SSX modding community's Multitool project: ``Patches.json`` with ``Lights.json``,
``Instances.json``, ``Splines.json``, ``Models.json``, ``Textures/`` and ``Lightmaps/`` beside it
(read by Blender's bxtools and Unity's IceSaw).

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
  section (empty, count 0; :func:`piste.formats.ssx.synth.pbd_bytes`) but the lights and the
  splines.  The Multitool's other files (``Materials.json``, ``Cameras.json``, ...) are not read
  by piste: each one present is named in :attr:`Project.notes` (what the new level lacks);
* **instances, splines, models** (``Instances.json``, ``Splines.json``, ``Models.json``;
  :mod:`piste.formats.ssx.multitool_objects` holds their facts): read and checked into
  :attr:`Project.instances` / :attr:`Project.splines` / :attr:`Project.models` (typed records
  that :func:`write_project` writes back field for field).  ``convert --to multitool`` writes
  ``Instances.json`` and ``Splines.json`` from the ``.pbd``'s sections (never ``Models.json``:
  piste does not decode the model section).  On import, with the recorded level, instances and
  spline segments are written over the level's records in place (counts must stay; unchanged
  ones keep their stored bytes), the instance hashes into the hash section's instance list;
  without it the new level gets the project's splines (the Multitool's rebuild) but **no
  instances**: an instance places one of the level's models, and a model is ``Meshes/*.obj``
  with ``Materials.json`` compiled into the model / material / mesh-data sections, which piste
  does not encode (named in :attr:`Project.notes`).  ``Models.json`` never changes a level;
* **lights** (``Lights.json``, ``{"Lights": [...]}``; SSX-Library ``LightJsonHandler.cs`` and the
  export/rebuild in ``TrickyLevelInterface.cs``, facts only): one object per 92-byte light record
  (:data:`~piste.formats.ssx.pbd.LIGHT_DTYPE`), fields ``LightName``, ``Type``, ``SpriteRes``,
  ``UnknownFloat1``, ``UnknownInt1``, ``Colour[3]``, ``Direction[3]``, ``Position[3]``,
  ``LowestXYZ[3]``, ``HighestXYZ[3]``, ``UnknownFloat2``, ``UnknownInt2``, ``UnknownFloat3``,
  ``UnknownInt3`` (the record's fields in file order, copied as they are; integers as signed
  32-bit) and ``Hash`` (the light's entry in the hash section's light list; 0 when it has none).
  ``LightName`` lives in the level's ``.map`` (which piste does not write): piste writes the
  Multitool's fallback ``Light_<i>`` and ignores the name on import.  Non-finite floats are the
  strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"`` (Json.NET's default).  ``convert --to
  multitool`` always writes it (as the Multitool does); on import, with the recorded level, the
  light records are written over the level's in place (a light whose fields did not change keeps
  its stored bytes; the count must stay, the later sections' offsets are not relocated), the
  hashes likewise when the level has a hash section with a light list of that count; without the
  recorded level the lights section holds the project's lights and, when there are any, the hash
  section holds only their hashes (:func:`piste.formats.ssx.pbd.hash_section_bytes`).  A project
  without ``Lights.json`` keeps the recorded level's lights (or has none);
* no ``Textures/`` folder: no texture bank; no ``Lightmaps/`` folder: no light-map bank.

Reading and writing are deterministic: the same input gives the same bytes.

API
---
::

    write_project(folder, pbd, textures=None, lightmaps=None, instances=None, splines=None, models=None)
                                                                     atomic per file
    read_project(folder) -> Project
    Project.to_level() -> (Pbd, SshBank textures or None, SshBank light maps or None)
    brighten(rgb) / darken(rgb)                                      the Multitool's RGB conventions
"""

from __future__ import annotations

import io
import json
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from piste.errors import FormatError, PisteError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import anchor, loads_json, read_regular
from piste.formats.ssx.multitool_objects import (
    INSTANCES_JSON, MODELS_JSON, SPLINES_JSON, MtInstances, MtModels, MtSplines, instances_from_json,
    instances_from_pbd, instances_in_place, instances_json, models_from_json, models_json, spline_sections,
    splines_from_json, splines_from_pbd, splines_in_place, splines_json,
)
from piste.formats.ssx.pbd import (
    COUNT_NAMES, LIGHT_DTYPE, LIGHT_SIZE, MAX_FILE_BYTES as MAX_PBD_BYTES, Pbd, hash_section_bytes, parse_pbd,
    records_from_arrays,
)
from piste.formats.ssx.ssh import INDEXED, PAGE_SIZE, SshBank, SshImage, half_bright, lightmap_bank
from piste.formats.ssx.synth import pbd_bytes

__all__ = ["write_project", "read_project", "Project", "brighten", "darken", "export_texture", "export_lightmap",
           "SOURCE_PBD", "SOURCE_JSON", "OTHER_JSON", "LIGHTS_JSON", "lights_json", "lights_from_json"]

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
OTHER_JSON = ("ParticleInstances.json", "Materials.json", "ParticleModels.json", "Cameras.json", "AIP.json",
              "SOP.json", "SSFLogic.json")
#: the Multitool's lights file (read and written)
LIGHTS_JSON = "Lights.json"
#: most lights a Lights.json may hold
MAX_LIGHTS = 1_000_000
#: Lights.json keys of the record's fields, in file order: (key, LIGHT_DTYPE field, kind)
_LIGHT_KEYS = (("Type", "type", "i"), ("SpriteRes", "sprite_res", "i"), ("UnknownFloat1", "unknown_float1", "f"),
               ("UnknownInt1", "unknown_int1", "i"), ("Colour", "colour", "v"), ("Direction", "direction", "v"),
               ("Position", "position", "v"), ("LowestXYZ", "lowest", "v"), ("HighestXYZ", "highest", "v"),
               ("UnknownFloat2", "unknown_float2", "f"), ("UnknownInt2", "unknown_int2", "i"),
               ("UnknownFloat3", "unknown_float3", "f"), ("UnknownInt3", "unknown_int3", "i"))
_NONFINITE = {"NaN": float("nan"), "Infinity": float("inf"), "-Infinity": float("-inf")}
_F32_MAX = float(np.finfo(np.float32).max)


# ----------------------------------------------------------------------------- the conventions
def brighten(rgb: np.ndarray) -> np.ndarray:
    """The Multitool's export brightening ``clamp(2c - 1, 0, 255)``: ``(...) uint8`` -> same shape."""
    return np.clip(np.asarray(rgb).astype(np.int16) * 2 - 1, 0, 255).astype(np.uint8)


def darken(rgb: np.ndarray) -> np.ndarray:
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


def export_lightmap(page: np.ndarray) -> np.ndarray:
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


# ----------------------------------------------------------------------------- lights
def _json_float(x: float) -> float | str:
    v = float(x)
    if np.isfinite(v):
        return v
    return "NaN" if np.isnan(v) else ("Infinity" if v > 0 else "-Infinity")


def lights_json(lights: np.ndarray, hashes: np.ndarray | None = None) -> dict:
    """``{"Lights": [...]}`` of light records ``(k,)`` :data:`~piste.formats.ssx.pbd.LIGHT_DTYPE`
    and their hashes ``(k,)`` (None: 0 each), the Multitool's ``Lights.json`` (module docstring)."""
    rec = np.asarray(lights, LIGHT_DTYPE).reshape(-1)
    h = np.zeros(len(rec), np.int64) if hashes is None else np.asarray(hashes, np.int64).reshape(-1)
    signed = {f: rec[f].astype(np.uint32).view(np.int32) for _, f, kind in _LIGHT_KEYS if kind == "i"}
    out = []
    for i in range(len(rec)):
        d: dict[str, Any] = {"LightName": f"Light_{i}"}
        for key, f, kind in _LIGHT_KEYS:
            if kind == "i":
                d[key] = int(signed[f][i])
            elif kind == "f":
                d[key] = _json_float(rec[f][i])
            else:
                d[key] = [_json_float(x) for x in rec[f][i]]
        d["Hash"] = int(np.int64(h[i]).astype(np.int32)) if -2**31 <= h[i] < 2**32 else 0
        out.append(d)
    return {"Lights": out}


def _light_number(v: object, path: str | os.PathLike[str], where: str, key: str, kind: str) -> int | float:
    """A Lights.json value as the record stores it: ``i`` a 32-bit integer (signed or unsigned),
    ``f`` a float32 (a number or "NaN"/"Infinity"/"-Infinity")."""
    if kind == "i":
        if isinstance(v, bool) or not isinstance(v, int) or not -2**31 <= v < 2**32:
            raise FormatError(path, f"{where}: {key} must be a 32-bit integer, got {v!r:.40}", field=key)
        return v & 0xFFFFFFFF
    if isinstance(v, str) and v in _NONFINITE:
        return _NONFINITE[v]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (
            abs(v) > _F32_MAX and not (isinstance(v, float) and np.isinf(v))):  # a huge int: no isfinite
        raise FormatError(path, f"{where}: {key} must be a number (float32), got {v!r:.40}", field=key)
    return float(v)


def lights_from_json(doc: Any, path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(records (k,) LIGHT_DTYPE, hashes (k,) int64)`` from a parsed ``Lights.json`` (``{"Lights":
    [...]}`` or a bare list).  Scalars the file leaves out are 0 (as the Multitool's JSON reader
    leaves them); the five vectors are required (3 numbers each)."""
    items = doc.get("Lights") if isinstance(doc, dict) else doc
    if isinstance(doc, dict) and "Lights" not in doc:
        items = []  # the Multitool reads {} as no lights
    if not isinstance(items, list):
        raise FormatError(path, "expected a list of lights (or {\"Lights\": [...]})", field="Lights")
    if len(items) > MAX_LIGHTS:
        raise FormatError(path, f"{len(items)} lights: more than the limit of {MAX_LIGHTS}", field="Lights")
    rec = np.zeros(len(items), LIGHT_DTYPE)
    hashes = np.zeros(len(items), np.int64)
    for i, d in enumerate(items):
        where = f"light {i}"
        if not isinstance(d, dict):
            raise FormatError(path, f"{where}: expected an object, got {type(d).__name__}", field="Lights")
        for key, f, kind in _LIGHT_KEYS:
            if kind == "v":
                v = d.get(key)
                if not isinstance(v, list) or len(v) != 3:
                    raise FormatError(path, f"{where}: {key} must be a list of 3 numbers, got {v!r:.60}", field=key)
                rec[f][i] = [_light_number(x, path, where, key, "f") for x in v]
            else:
                rec[f][i] = _light_number(d.get(key, 0), path, where, key, kind)
        h = _light_number(d.get("Hash", 0), path, where, "Hash", "i")
        hashes[i] = h - (1 << 32) if h >= 1 << 31 else h
    return rec, hashes


def _light_keys(rec: np.ndarray, hashes: np.ndarray | None) -> list:
    """Per light, its Lights.json fields without the name, comparable with == (NaN as a string)."""
    doc = lights_json(rec, hashes)["Lights"]
    return [json.dumps({k: v for k, v in d.items() if k != "LightName"}, sort_keys=True) for d in doc]


# ----------------------------------------------------------------------------- writing
def write_project(folder: str | os.PathLike[str], pbd: Pbd, textures: SshBank | None = None,
                  lightmaps: SshBank | None = None, instances: MtInstances | None = None, splines: MtSplines | None = None,
                  models: MtModels | None = None) -> Path:
    """Write ``Patches.json``, ``Lights.json``, ``Instances.json``, ``Splines.json``,
    ``Textures/NAME.png`` and ``Lightmaps/NNNN.png`` into ``folder`` the Multitool's way (module
    docstring), and piste's record of the level (``PisteLevel.pbd``, ``PisteLevel.json``).
    ``instances`` / ``splines`` (default: the level's own, from its sections) and ``models``
    (default: no ``Models.json``) are written as given: a project read by :func:`read_project`
    passes its records here to come back field for field.  Returns the path of ``Patches.json``."""
    inst = instances if instances is not None else instances_from_pbd(pbd)
    spl = splines if splines is not None else splines_from_pbd(pbd)
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
    write_bytes_atomic(folder / LIGHTS_JSON, json.dumps(lights_json(pbd.read_lights(), pbd.light_hashes()),
                                                        indent=1).encode())
    write_bytes_atomic(folder / INSTANCES_JSON, json.dumps(instances_json(inst), indent=1).encode())
    write_bytes_atomic(folder / SPLINES_JSON, json.dumps(splines_json(spl), indent=1).encode())
    if models is not None:
        write_bytes_atomic(folder / MODELS_JSON, json.dumps(models_json(models), indent=1).encode())
    if textures is not None and tex_names is not None:
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
    lights: np.ndarray | None = None      # (k,) LIGHT_DTYPE from Lights.json, None without the file
    light_hashes: np.ndarray | None = None  # (k,) int64
    instances: MtInstances | None = None  # Instances.json, None without the file
    splines: MtSplines | None = None      # Splines.json
    models: MtModels | None = None        # Models.json (never changes the level)

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
            pbd = parse_pbd(self.source.raw, self.source.path)  # its errors name PisteLevel.pbd
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
            if self.lights is not None:
                self._lights_in_place(pbd, data)
            base = self.path.parent
            if self.instances is not None:
                self.notes += instances_in_place(pbd, data, self.instances, base / INSTANCES_JSON, SOURCE_PBD)
            if self.splines is not None:
                splines_in_place(pbd, data, self.splines, base / SPLINES_JSON, SOURCE_PBD)
            return parse_pbd(bytes(data), self.path), textures, lightmaps
        rec = records_from_arrays(self.control_points, self.uv, self.lightmap_rect, self.lightmap_page,
                                  self.texture_index, self.surface_type, self.trick_only)
        platform = self.source.platform if self.source is not None else 1
        sections: dict[str, Any] = {}
        if self.lights is not None and len(self.lights):
            assert self.light_hashes is not None  # read_project sets both from Lights.json
            sections = {"lights": (len(self.lights), self.lights.tobytes()),
                        "hash": (None, hash_section_bytes(self.light_hashes))}
        if self.splines is not None and len(self.splines):
            sections.update(spline_sections(self.splines, self.path.parent / SPLINES_JSON))
        return parse_pbd(pbd_bytes(rec, n_tex, platform, sections), self.path), textures, lightmaps

    def _lights_in_place(self, pbd: Pbd, data: bytearray) -> None:
        """Write the project's lights over the recorded level's (same count), and their hashes over
        its hash section's light list when it has one of that count; unchanged lights and hashes
        keep their stored bytes."""
        assert self.lights is not None  # to_level calls this only with lights
        lpath = self.path.parent / LIGHTS_JSON
        old = pbd.read_lights()
        k = len(self.lights)
        if k != len(old):
            raise FormatError(lpath, f"{k} lights, but {SOURCE_PBD} holds {len(old)}: the count of a recorded "
                                     "level's lights cannot change (the sections after them hold absolute offsets "
                                     f"piste does not relocate); remove {SOURCE_JSON} to build the level from the "
                                     "project's files alone", field="Lights")
        old_h = pbd.light_hashes()
        same = [a == b for a, b in zip(_light_keys(self.lights, None), _light_keys(old, None))]
        rec = self.lights.copy()
        keep = np.array(same, bool)
        rec[keep] = old[keep]
        off = pbd.offsets["lights"]
        data[off:off + k * LIGHT_SIZE] = np.ascontiguousarray(rec, LIGHT_DTYPE).tobytes()
        h = pbd.hash_header()
        want = np.asarray(self.light_hashes, np.int64)
        if old_h is not None and np.array_equal(old_h, want):
            return
        if h is not None and h["count_lights"] == k:
            lo = pbd.offsets["hash"] + h["offset_lights"]
            data[lo:lo + 8 * k] = hash_section_bytes(want)[4 * 13:]
        elif want.any():
            self.notes.append(f"{LIGHTS_JSON}: the lights' Hash values are not kept: {SOURCE_PBD} has no hash "
                              f"section with a list of {k} light hashes to write them into")


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


def _read_source(folder: Path) -> tuple[Pbd | None, list[str]]:
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


def read_project(folder: str | os.PathLike[str]) -> Project:
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
    source, recorded_names = _read_source(folder)
    cp = np.zeros((n, 16, 3))
    uv = np.zeros((n, 4, 2), np.float32)
    rect = np.zeros((n, 4), np.float32)
    page = np.zeros(n, np.int16)
    tex = np.zeros(n, np.int16)
    surf = np.zeros(n, np.uint32)
    trick = np.zeros(n, bool)
    names: list[str] = []
    files = list(recorded_names)  # texture i's file name: the recorded bank order, then first appearance
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
                first = first_use.get(name)
                why = f"patch {first}: TexturePath {name!r}" if first is not None else f"texture {name!r} ({SOURCE_JSON})"
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
    lpath = folder / LIGHTS_JSON
    if lpath.exists() or lpath.is_symlink():
        proj.lights, proj.light_hashes = lights_from_json(
            loads_json(read_regular(lpath, MAX_JSON_BYTES, what="lights file"), lpath), lpath)
    for name, parse, attr in ((INSTANCES_JSON, instances_from_json, "instances"),
                              (SPLINES_JSON, splines_from_json, "splines"), (MODELS_JSON, models_from_json, "models")):
        opath = folder / name
        if opath.exists() or opath.is_symlink():
            setattr(proj, attr, parse(loads_json(read_regular(opath, MAX_JSON_BYTES, what="project file"), opath), opath))
    if source is not None and len(source) != n:
        skip = ("patches", "textures", "lightmap_size") + (("lights",) if proj.lights is not None else ()) + (
            ("splines", "spline_segments") if proj.splines is not None else ())
        kept = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in source.counts.items() if v and k not in skip)
        proj.notes.append(f"{SOURCE_PBD} holds {len(source)} patches, Patches.json {n}: the level's other sections "
                          f"({kept or 'none'}) hold absolute offsets piste does not relocate, so the new level has "
                          "the minimal default (empty) for them")
    recorded = source is not None and len(source) == n
    if proj.instances is not None and len(proj.instances) and not recorded:
        proj.notes.append(f"{INSTANCES_JSON}: {len(proj.instances)} instances read but not written into the new level: "
                          "an instance places one of the level's models, and piste does not encode models (Models.json "
                          "with Meshes/*.obj and Materials.json compiled into the model, material and mesh-data "
                          "sections)")
    if proj.models is not None and len(proj.models):
        proj.notes.append(f"{MODELS_JSON}: {len(proj.models)} models read and checked, not encoded: "
                          + (f"the level's models come from {SOURCE_PBD}" if recorded else "the new level has none"))
    for other in OTHER_JSON:
        if (folder / other).exists():
            if source is not None and len(source) == n:
                proj.notes.append(f"{other}: not read by piste (the level's sections come from {SOURCE_PBD})")
            else:
                proj.notes.append(f"{other}: not read by piste: the new level has none of what it holds")
    return proj
