"""The scene description: a TOML file a person writes and reads, parsed and validated.

A scene names its terrain, the riders and objects on it, the lights and cameras (inline, or
imported from a glTF file an artist lit and framed in Blender), and the pre-processing settings
(light-map resolution, LOD thresholds, visibility cells).  ``piste build`` turns it into a
``.piste`` bundle; ``piste render`` and ``piste view`` show it.  Every path is relative to the
scene file.  Every table and key is optional except where noted::

    name = "my run"
    # Every path below (and every URI inside a glTF it names) must stay inside the folder of the
    # file that names it: '..' out of it, absolute paths and symbolic links are refused.  Only the
    # user widens that, never the file: `--allow-path DIR` on the command line or the
    # PISTE_ALLOW_PATHS environment variable (piste.formats.safe_io); an `allow_paths` key is an error.

    [terrain]
    source = "default"            # "default" (the seeded course), a .bpt, a saved net (.npz),
                                  # a height field: a PNG (8- or 16-bit grey) or an .npz array,
                                  # or an SSX Tricky level (.pbd)
    ssx_pbd = "LEVEL.pbd"         # (instead of source) an SSX Tricky level: its own textures
                                  # (LEVEL.ssh) and light maps (LEVEL_L.ssh) from beside it
    seed = 0                      # default course seed
    spacing = 3.125               # height field: metres between samples (or [dx, dy]); an .npz
                                  # may carry 'dx'/'dy' or 'spacing' instead
    height_scale = 1.0            # height field: metres per unit (per grey level of a PNG)
    height_offset = 0.0           # metres added to every height
    key = "elevation"             # .npz height field: the array to read (default: the first 2-D one)
    samples_per_patch = 4         # height field: sample intervals per patch side
    smooth = false                # height field: C2 fit instead of C0
    nodata = "nearest"            # GeoTIFF (.tif with georeferencing; spacing from its tags):
                                  # missing samples "nearest" | "error" | a height in metres
    vertical_units = "metre"      # GeoTIFF: override the file's vertical unit (metre, foot, us_survey_foot)
    tiles = "world.tiles"         # large worlds: build a tiled net folder (piste.terrain.tiles)
    tile_patches = 64             #   patches per tile side

    [lightmap]
    res = 8                       # texels per patch side
    shadows = true                # terrain self-shadowing in the bake
    gutter = 1
    bounces = 0                   # diffuse inter-reflections + sky light (piste.lighting.gi); 0 = direct only
    sun_radius = 0.0              # degrees: an area sun's soft shadows (the real sun: 0.27); 0 = hard

    [lod]
    preset = "piste"              # near/far defaults: "piste" (60 / 180) or "ssx_tricky" (30 / 150 m,
                                  # the game's; the default for an ssx_pbd terrain)
    near = 60.0                   # terrain: edges nearer than this get 8 vertices,
    far = 180.0                   #   nearer than far 6, the rest 4
    character = [14.0, 35.0]      # riders: high -> medium -> low LOD distances (when character_pixels = 0)
    character_pixels = 1.0        # riders: each takes the coarsest LOD whose error projects under this many
                                  #   pixels (the objects' rule); 0 = by the distances above
    ratios = [1.0, 0.5, 0.25]     # riders: triangle ratio of each LOD
    morph = true                  # terrain: geomorph between 4/6/8 (false: the talk's popping;
                                  #   `--lod-morph on|off` on demo/render/view overrides)

    [visibility]
    enabled = true
    cell = 50.0                   # metres: the course's xy grid of visibility cells
    eye_heights = [1.7, 9.0]      # metres above the snow of the sampled eye points
    method = "auto"               # "horizon" (height fields), "rays" (any net) or "auto"

    [render]
    size = [640, 448]
    lightmap_mode = "modulate"    # or "ps2"
    fog = "auto"                  # density per metre (0: none) or "auto" (6e-4 scaled to the scene's size)
    face = "morph"                # riders' faces: "morph" targets, their "null_bones" fit, or "off"
    object_lod = 1.0              # objects' levels of detail: the simplification error an instance
                                  #   may show, in pixels (0: every object drawn in full)
    aa = "off"                    # anti-aliasing: "off", "msaa2|4|8" or "fxaa" (`--aa` overrides)
    dof = [20.0, 0.05]            # depth of field: focus distance and lens radius in metres (default:
                                  #   none, a pinhole; `--dof FOCUS_M:APERTURE` overrides)
    soft_shadows = false          # rider shadows with the sun's penumbra (PCSS; `--soft-shadows`)
    occlusion = false             # cull what the near terrain hides (`--occlusion on|off`)

    [pack]                        # instead of [[riders]], on the default course: riders following the
    follow = "track"              #   track (piste demo's six, the camera chasing the first)
    start = 0.12                  # fraction of the track where the first rider is at t = 0

    [auto_objects]                # instead of [[objects]], on the default course: trees, signs, rocks
    seed = 0                      #   and rails placed along the track (piste.world.objects.place_objects)
    trees = 220
    signs = 16
    rocks = 40
    rails = 6

    [[gltf]]                      # lights and cameras placed in Blender (KHR_lights_punctual)
    file = "lights.gltf"
    lights = true
    cameras = true
    offset = [0.0, 0.0, 0.0]      # piste position (metres, Z up) of the glTF origin
    scale = 1.0                   # metres per glTF unit
    up = "y"                      # the file's up axis: "y" (glTF, Blender's export) or "z"
    white = 683.0                 # lux that map to piste intensity 1.0 (see piste.pipeline.gltf_import)

    [[riders]]
    name = "rider 1"
    model = "builtin:rider"       # or a .gltf/.glb file, or "ssx:RIDER.mpf" (SSX Tricky)
    texture = "RIDER.ssh"         # ssx: models only: the texture bank (default: RIDER.ssh beside it)
    position = [200.0, 150.0]     # x, y on the snow (z from the surface), or [x, y, z]
    heading = 0.0                 # degrees about +z, 0 = travelling +y (down the course)
    clip = "ride"
    phase = 0.0                   # seconds into the clip at t = 0
    clips_from = "Fox.glb"        # optional: play this file's clips, retargeted onto the model
                                  #   (ssx: models also take an SSX Tricky .afl bank, no bone_map)
    bone_map = "builtin"          #   by the built-in map, or { "b_Hip_01" = "pelvis", ... }
    scale = 1.0

    [[objects]]
    model = "builtin:tree"        # builtin:tree | builtin:sign | builtin:rock | builtin:rail | a glTF
    position = [220.0, 160.0]
    heading = 0.0
    scale = 1.0

    [[tile_objects]]              # a tiled build (terrain.tiles or --dask): objects placed on every tile
    kind = "tree"                 #   tree | sign | rock | rail (piste.pipeline.tile_objects)
    density = 6.0                 #   candidates a hectare
    slope = [0.0, 30.0]           #   degrees where one is kept
    altitude = [0.0, 2400.0]      #   metres where one is kept (default: any)
    scale = [0.7, 1.4]            #   size range

    [[lights]]                    # piste.lighting fields; type is the kind
    type = "directional"          # ambient | directional | point | spot
    direction = [0.3, 0.8, -0.5]
    color = [1.0, 0.9, 0.8]
    intensity = 1.0

    [[cameras]]
    name = "start"
    eye = [200.0, 50.0, 300.0]
    target = [200.0, 150.0, 260.0]
    fov = 60.0                    # vertical, degrees, in (0, 180)
    near = 0.5                    # metres, >= 1e-4; far / near <= 1e7
    far = 4000.0                  # default: 4 km, or what reaches the whole terrain if that is farther
    # or a camera flying down the default course's track (from fraction a to b over --frames):
    # track = [0.1, 0.4]
    # height = 9.0

Errors: an unknown key, a wrong type or a missing file raise :class:`~piste.errors.ConfigError`
naming the file, the line and the key (``scene.toml, line 12, key 'riders[1].clip': ...``);
tomllib gives no line numbers, so :func:`key_lines` scans the text for them.

API
---
load_scene(path) -> SceneFile      read and validate a scene file
loads_scene(text, path) -> SceneFile
key_lines(text) -> dict            ('riders', 0, 'clip') -> line number
SceneFile, TerrainSpec, ActorSpec, GltfSpec, CameraSpec, LightmapSpec, LodSpec, VisibilitySpec, RenderSpec
SCENE_SECTIONS                     top-level key -> SceneSection(parse -> typed value), parsed in order
register_section(section, after=) / unregister_section(name)   (ARCHITECTURE.md: how to add one)
SceneTable                         what a section's parse reads: allow, get, error (file, line, key)
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from piste.errors import ConfigError, PisteError, ValidationError
from piste.formats.gltf.schema import precheck_gltf
from piste.formats.ssx.mpf_model import mpf_partners
from piste.formats.safe_io import (MAX_TOML_BYTES, check_regular, confined_file, confined_folder, loads_toml, open_file,
                                   read_regular, resolve_reference, user_allow_paths)
from piste.lighting.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from piste.world.object_lod import DEFAULT_LOD_PIXELS

#: the kinds [[tile_objects]] may name (piste.world.objects.OBJECT_KINDS)
TILE_OBJECT_KINDS = ("tree", "sign", "rock", "rail")

__all__ = [
    "SceneFile",
    "TerrainSpec",
    "ActorSpec",
    "GltfSpec",
    "CameraSpec",
    "LightmapSpec",
    "LodSpec",
    "VisibilitySpec",
    "RenderSpec",
    "PackSpec",
    "AutoObjectsSpec",
    "TileObjectSpec",
    "load_scene",
    "loads_scene",
    "key_lines",
    "SceneError",
    "BUILTIN_MODELS",
    "SceneSection",
    "SceneTable",
    "SCENE_SECTIONS",
    "register_section",
    "unregister_section",
]

BUILTIN_MODELS = ("builtin:rider", "builtin:tree", "builtin:sign", "builtin:rock", "builtin:rail")
HEIGHTFIELD_IMAGES = (".png", ".tif", ".tiff", ".pgm")
#: [lod] preset -> (near, far) metres: piste's own, and SSX Tricky's 3000 / 15000 game units
LOD_PRESETS = {"piste": (60.0, 180.0), "ssx_tricky": (30.0, 150.0)}
#: largest absolute coordinate in metres a scene may give (eyes, targets, positions, offsets): 100,000 km
MAX_SCENE_COORDINATE = 1e8
#: seeds are unsigned 32-bit (numpy's generators refuse negative ones with a raw ValueError)
MAX_SEED = 2**32 - 1
#: a camera's near plane, its far plane (metres) and their largest ratio (1e-300 / 1e300 made the
#: projection singular: a LinAlgError deep in the renderer)
MIN_NEAR, MAX_FAR, MAX_FAR_NEAR_RATIO = 1e-4, 1e8, 1e7


#: a light given inline (``[[lights]]``)
_Light = AmbientLight | DirectionalLight | PointLight | SpotLight


class SceneError(ConfigError):
    """A mistake in a scene file: ``path``, ``line`` (1-based or None) and ``key`` (dotted)."""

    def __init__(self, path: str | os.PathLike[str] | None, message: str, line: int | None = None,
                 key: str | None = None) -> None:
        self.path = str(path) if path is not None else None
        self.line = line
        self.key = key
        where = self.path or "<scene>"
        if line is not None:
            where += f", line {line}"
        if key is not None:
            where += f", key {key!r}"
        super().__init__(f"{where}: {message}")


# ----------------------------------------------------------------------------- line numbers
_ARRAY_HEADER = re.compile(r"^\s*\[\[\s*([^\]]+?)\s*\]\]\s*(#.*)?$")
_TABLE_HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")
_KEY = re.compile(r"""^\s*((?:[A-Za-z0-9_\-]+|"[^"]*"|'[^']*')(?:\s*\.\s*(?:[A-Za-z0-9_\-]+|"[^"]*"|'[^']*'))*)\s*=""")


def _split_key(text: str) -> tuple[str, ...]:
    parts = re.findall(r"""[A-Za-z0-9_\-]+|"[^"]*"|'[^']*'""", text)
    return tuple(p[1:-1] if p[:1] in "\"'" else p for p in parts)


def key_lines(text: str) -> dict[tuple[str | int, ...], int]:
    """Line number (1-based) of every table header and key of a TOML document.

    Keys are paths: ``("terrain",)`` for a ``[terrain]`` header, ``("terrain", "seed")`` for a key
    in it, ``("riders", 1)`` for the second ``[[riders]]`` header and ``("riders", 1, "clip")`` for
    a key in it.  Multi-line strings and arrays are skipped over.  A best-effort scan (tomllib
    gives no positions): a key it cannot place is simply absent.
    """
    out: dict = {}
    counts: dict = {}
    prefix: tuple = ()
    in_string = None
    depth = 0
    for no, line in enumerate(text.splitlines(), start=1):
        if in_string:
            if in_string in line:
                in_string = None
            continue
        if depth > 0:  # inside a multi-line array / inline table
            depth += _bracket_depth(line)
            continue
        m = _ARRAY_HEADER.match(line)
        if m:
            name = _split_key(m.group(1))
            i = counts.get(name, -1) + 1
            counts[name] = i
            # drop counters of sub-arrays of an earlier element
            for k in [k for k in counts if len(k) > len(name) and k[: len(name)] == name]:
                del counts[k]
            prefix = _indexed(name, counts)
            out.setdefault(prefix, no)
            continue
        m = _TABLE_HEADER.match(line)
        if m and not line.lstrip().startswith("[["):
            prefix = _indexed(_split_key(m.group(1)), counts)
            out.setdefault(prefix, no)
            continue
        m = _KEY.match(line)
        if m:
            out.setdefault(prefix + _split_key(m.group(1)), no)
            rest = line[m.end():]
            for q in ('"""', "'''"):
                if rest.count(q) == 1:
                    in_string = q
            if not in_string:
                depth = max(0, _bracket_depth(rest))
    return out


def _indexed(name: tuple[str, ...], counts: dict[tuple[str | int, ...], int]) -> tuple[str | int, ...]:
    """``("riders", "x")`` -> ``("riders", 3, "x")`` when riders is an array of tables (its last element)."""
    out: tuple = ()
    for part in name:
        out = out + (part,)
        if out in counts:
            out = out + (counts[out],)
    return out


def _bracket_depth(text: str) -> int:
    text = re.sub(r'"(?:\\.|[^"\\])*"|\'[^\']*\'', "", text)
    text = text.split("#", 1)[0]
    return text.count("[") + text.count("{") - text.count("]") - text.count("}")


# ----------------------------------------------------------------------------- specs
@dataclass
class TerrainSpec:
    """Where the terrain comes from.  ``kind``: ``default`` | ``bpt`` | ``net`` (saved PatchNet .npz)
    | ``heightfield`` (an image or an .npz array).  ``path`` is absolute (None for the default course)."""

    kind: str = "default"
    path: Path | None = None
    seed: int = 0
    spacing: tuple[float, float] | None = None
    height_scale: float = 1.0
    height_offset: float = 0.0
    key: str | None = None
    samples_per_patch: int = 4
    smooth: bool = False
    nodata: float | str = "nearest"
    vertical_units: str | None = None
    tiles: Path | None = None
    tile_patches: int = 64


@dataclass
class ActorSpec:
    """A rider or an object: ``model`` is ``builtin:<kind>`` or an absolute glTF path."""

    name: str
    model: str
    position: tuple[float, ...]
    heading: float = 0.0
    clip: str | None = None
    phase: float = 0.0
    scale: float = 1.0
    line: int | None = None
    clips_from: str | None = None     # riders: a glTF file whose clips are retargeted onto the model (or an .afl)
    bone_map: str | dict[str, str] | None = None           # riders: "builtin" or {clip bone: model bone} (piste.character.retarget)
    texture: str | None = None        # ssx: riders: the .ssh texture bank given (None: found beside the .mpf)

    @property
    def builtin(self) -> str | None:
        return self.model.split(":", 1)[1] if self.model.startswith("builtin:") else None


@dataclass
class GltfSpec:
    """Lights and cameras to import from a glTF file (see :mod:`piste.pipeline.gltf_import`)."""

    file: Path
    lights: bool = True
    cameras: bool = True
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale: float = 1.0
    up: str = "y"
    white: float = 683.0
    allow_paths: tuple[Path, ...] = ()  # folders the user allowed besides the model's own (--allow-path, PISTE_ALLOW_PATHS)


@dataclass
class CameraSpec:
    """An inline camera as the scene file describes it: fixed (``eye``, ``target``) or flying down
    the track (``track = (a, b)``), planes left open as None.  A description, not a second camera
    type: the build (:func:`piste.pipeline.build.scene_cameras`) turns it into the one
    :class:`piste.scene_data.Camera` once the terrain (and so the open planes) is known."""

    name: str
    eye: tuple | None = None
    target: tuple | None = None
    up: tuple = (0.0, 0.0, 1.0)
    fov: float = 60.0
    near: float | None = None  # None: 0.5 m (more for a far plane beyond 50 km: far / near <= 1e5)
    far: float | None = None   # None: 4 km or what reaches the whole terrain (piste.world.camera.far_for_extent)
    track: tuple | None = None
    height: float = 9.0


@dataclass
class LightmapSpec:
    res: int = 8
    shadows: bool = True
    gutter: int = 1
    bounces: int = 0
    sun_radius: float = 0.0


@dataclass
class LodSpec:
    near: float = 60.0
    far: float = 180.0
    character: tuple[float, float] = (14.0, 35.0)
    ratios: tuple[float, ...] = (1.0, 0.5, 0.25)
    morph: bool = True  # geomorph terrain vertices between levels (False: the talk's exact popping)
    character_pixels: float = 1.0  # riders' LOD by projected error (pixels); 0: by ``character`` distances


@dataclass
class VisibilitySpec:
    enabled: bool = True
    cell: float = 50.0
    eye_heights: tuple[float, ...] = (1.7, 9.0)
    method: str = "auto"


@dataclass
class RenderSpec:
    size: tuple[int, int] = (640, 448)
    lightmap_mode: str = "modulate"
    fog: float | str = "auto"     # density per metre, or "auto" (scaled to the scene's size)
    face: str = "morph"      # "morph", "null_bones" or "off"
    object_lod: float = DEFAULT_LOD_PIXELS  # pixels of simplification error an object may show (0: full meshes)
    aa: str = "off"          # anti-aliasing: "off", "msaa2", "msaa4", "msaa8" or "fxaa"
    dof: list[float] | None = None       # depth of field: [focus metres, aperture metres] or None (off)
    soft_shadows: bool = False  # percentage-closer soft rider shadows
    occlusion: bool = False  # occlusion culling of terrain patches and objects


#: [auto_objects] keys and their defaults (piste.world.objects.place_objects' counts)
AUTO_OBJECT_COUNTS = {"trees": 220, "signs": 16, "rocks": 40, "rails": 6}


@dataclass(frozen=True)
class PackSpec:
    """``[pack]``: the default course's riders following the track (``start``: fraction of the
    track where the first rider is at t = 0)."""

    follow: str = "track"
    start: float = 0.12

    def as_dict(self) -> dict[str, Any]:
        """The manifest's ``pack`` entry: ``{"follow", "start"}``."""
        return {"follow": self.follow, "start": self.start}


@dataclass(frozen=True)
class AutoObjectsSpec:
    """``[auto_objects]``: the course's objects placed along the track (a seed and a count of each
    kind, :data:`AUTO_OBJECT_COUNTS` by default)."""

    seed: int = 0
    trees: int = AUTO_OBJECT_COUNTS["trees"]
    signs: int = AUTO_OBJECT_COUNTS["signs"]
    rocks: int = AUTO_OBJECT_COUNTS["rocks"]
    rails: int = AUTO_OBJECT_COUNTS["rails"]

    def as_dict(self) -> dict[str, int]:
        """The manifest's ``auto_objects`` entry: ``{"seed", "trees", "signs", "rocks", "rails"}``."""
        return {"seed": self.seed, "trees": self.trees, "signs": self.signs, "rocks": self.rocks, "rails": self.rails}


@dataclass(frozen=True)
class TileObjectSpec:
    """One ``[[tile_objects]]`` rule (:class:`piste.pipeline.tile_objects.ObjectRule`'s fields):
    a kind, candidates a hectare, and the (min, max) slope in degrees, altitude in metres (None:
    any) and scale where one is kept."""

    kind: str
    density: float
    slope: tuple[float, float] = (0.0, 90.0)
    altitude: tuple[float, float] | None = None
    scale: tuple[float, float] = (0.7, 1.4)

    def rule_fields(self) -> dict[str, Any]:
        """The keyword arguments of ``ObjectRule`` (``altitude`` only when given)."""
        out: dict[str, Any] = {"kind": self.kind, "density": self.density, "slope": self.slope, "scale": self.scale}
        if self.altitude is not None:
            out["altitude"] = self.altitude
        return out


@dataclass
class SceneFile:
    """A parsed, validated scene (see the module docstring).  ``lights`` holds piste light
    objects (:mod:`piste.lighting.lights`) given inline; glTF lights are imported at build time."""

    path: Path
    name: str
    terrain: TerrainSpec = field(default_factory=TerrainSpec)
    riders: list[ActorSpec] = field(default_factory=list)
    objects: list[ActorSpec] = field(default_factory=list)
    lights: tuple[_Light, ...] = ()
    gltf: list[GltfSpec] = field(default_factory=list)
    cameras: list[CameraSpec] = field(default_factory=list)
    lightmap: LightmapSpec = field(default_factory=LightmapSpec)
    lod: LodSpec = field(default_factory=LodSpec)
    visibility: VisibilitySpec = field(default_factory=VisibilitySpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    pack: PackSpec | None = None                  # [pack]
    auto_objects: AutoObjectsSpec | None = None   # [auto_objects]
    tile_objects: list[TileObjectSpec] = field(default_factory=list)  # [[tile_objects]]
    text: str = ""
    allow_paths: tuple[Path, ...] = ()  # folders the user allowed (--allow-path, PISTE_ALLOW_PATHS) when it was loaded
    sections: dict[str, Any] = field(default_factory=dict)  # registered sections without a field here: name -> value

    def source_files(self) -> list[Path]:
        """Every file the scene reads (the TOML, terrain, glTF files and their buffers and images),
        absolute, sorted: what a watcher polls and what the build cache hashes."""
        files = {Path(self.path).resolve()}
        if self.terrain.path is not None:
            files.add(Path(self.terrain.path))
        gltfs = [g.file for g in self.gltf] + [Path(a.model) for a in self.riders + self.objects if a.builtin is None]
        gltfs += [Path(a.clips_from) for a in self.riders if a.clips_from]  # a glTF's or an .afl's clips
        for g in gltfs:
            files.add(Path(g))
            files.update(_gltf_dependencies(Path(g), self.allow_paths))
        for a in self.riders:  # an .mpf's _head.mpf partner and texture banks
            if a.model.lower().endswith(".mpf"):
                head, banks = mpf_partners(a.model, a.texture)
                files.update(Path(f).resolve() for f in ([head] if head is not None else []) + banks)
        return sorted(files)


def _gltf_dependencies(path: Path, allow_paths: tuple[Path, ...] = ()) -> list[Path]:
    """Buffers and images a ``.gltf`` references by relative URI (``.glb`` files embed theirs).

    Only references the loader would read (regular files inside the model's folder or
    ``allow_paths``, :mod:`piste.formats.safe_io`) are listed: a hostile URI naming a device, a pipe
    or a file elsewhere is never hashed or polled; loading the model reports it."""
    if path.suffix.lower() != ".gltf" or not path.is_file():
        return []
    try:
        doc = precheck_gltf(path)
    except PisteError:
        return []
    out = []
    for item in list(doc.get("buffers") or []) + list(doc.get("images") or []):
        uri = item.get("uri") if isinstance(item, dict) else None
        if isinstance(uri, str) and not uri.startswith("data:"):
            try:
                f = resolve_reference(path, uri, allow_paths)
                check_regular(f, 1 << 62)
            except PisteError:
                continue
            out.append(f)
    return out


# ----------------------------------------------------------------------------- the parser
class SceneTable:
    """Typed access to one table of the document, with errors naming file, line and key."""

    def __init__(self, path: Path, lines: dict[tuple[str | int, ...], int], table: dict[str, Any],
                 where: tuple[str | int, ...], label: str) -> None:
        self.path, self.lines, self.table, self.where, self.label = path, lines, table, where, label

    def line(self, key: str | None = None) -> int | None:
        if key is not None and self.where + (key,) in self.lines:
            return self.lines[self.where + (key,)]
        return self.lines.get(self.where)

    def name(self, key: str) -> str:
        return f"{self.label}.{key}" if self.label else key

    @property
    def base(self) -> Path:
        """The folder of the scene file (relative paths resolve against it)."""
        return Path(self.path).resolve().parent

    def file(self, key: str, suffixes: Sequence[str] | None = None) -> Path:
        """The regular file ``key`` names (required), confined to the scene's folder or a folder the
        user allowed, no symbolic links (:mod:`piste.formats.safe_io`); ``suffixes``: the ones taken."""
        return _file(self, key, self.base, suffixes)

    def bounded(self, key: str, lo: float, hi: float, default: Any = None, kind: str = "float",
                what: str = "a number") -> Any:
        """``get(key, kind, default)`` (a number or a vector of them) checked to lie in ``[lo, hi]``."""
        return _bounded(self, key, self.get(key, kind, default), lo, hi, what)

    def error(self, key: str | None, message: str) -> SceneError:
        return SceneError(self.path, message, line=self.line(key), key=self.name(key) if key else self.label or None)

    def allow(self, keys: Collection[str]) -> None:
        for k in self.table:
            if k not in keys:
                raise self.error(k, f"unknown key {k!r}: expected one of {', '.join(sorted(keys))}")

    def get(self, key: str, kind: str, default: Any = None, required: bool = False) -> Any:
        if key not in self.table:
            if required:
                raise SceneError(self.path, f"missing key {key!r}", line=self.line(), key=self.name(key))
            return default
        v = self.table[key]
        return _convert(self, key, v, kind)


def _type_name(v: object) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
            dict: "a table"}.get(type(v), type(v).__name__)


def _convert(c: SceneTable, key: str, v: Any, kind: str) -> Any:
    if kind == "str":
        if not isinstance(v, str):
            raise c.error(key, f"expected a string, got {_type_name(v)} ({v!r})")
        return v
    if kind == "bool":
        if not isinstance(v, bool):
            raise c.error(key, f"expected true or false, got {_type_name(v)} ({v!r})")
        return v
    if kind == "int":
        if isinstance(v, bool) or not isinstance(v, int):
            raise c.error(key, f"expected an integer, got {_type_name(v)} ({v!r})")
        return v
    if kind in ("float", "pos"):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise c.error(key, f"expected a finite number, got {_type_name(v)} ({v!r})")
        if kind == "pos" and not v > 0:
            raise c.error(key, f"expected a number > 0, got {v!r}")
        return float(v)
    if kind.startswith("vec") or kind == "floats":
        n = {"vec2": (2,), "vec3": (3,), "vec23": (2, 3), "floats": None}[kind]
        ok = isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
        if not ok or (n is not None and len(v) not in n) or (n is None and not v):
            want = "an array of numbers" if n is None else f"an array of {' or '.join(map(str, n))} numbers"
            raise c.error(key, f"expected {want}, got {_type_name(v)} ({v!r})")
        return tuple(float(x) for x in v)
    raise AssertionError(kind)


def _bounded(c: SceneTable, key: str, v: Any, lo: float, hi: float, what: str = "a number") -> Any:
    """``v`` (a number, a tuple of numbers or None) after checking ``lo <= x <= hi`` for each."""
    vals = () if v is None else v if isinstance(v, tuple) else (v,)
    if not all(lo <= x <= hi for x in vals):
        raise c.error(key, f"expected {what} in [{lo:g}, {hi:g}], got {list(v) if isinstance(v, tuple) else v!r}")
    return v


def _table(c_parent: SceneTable, key: str) -> SceneTable:
    v = c_parent.table.get(key, {})
    if not isinstance(v, dict):
        raise c_parent.error(key, f"expected a table [{key}], got {_type_name(v)}")
    return SceneTable(c_parent.path, c_parent.lines, v, (key,), key)


def _array(c_parent: SceneTable, key: str) -> list:
    v = c_parent.table.get(key, [])
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise c_parent.error(key, f"expected an array of tables [[{key}]]")
    return [SceneTable(c_parent.path, c_parent.lines, x, (key, i), f"{key}[{i}]") for i, x in enumerate(v)]


def _file(c: SceneTable, key: str, base: Path, suffixes: Sequence[str] | None = None, value: str | None = None) -> Path:
    """The regular file scene key ``key`` names, confined to the scene's folder (or a folder the user
    allowed) and reached without symbolic links (:func:`piste.formats.safe_io.confined_file`)."""
    rel = c.get(key, "str", required=True) if value is None else value
    try:
        p = confined_file(c.path, rel, field=c.name(key))
    except PisteError as exc:
        reason = getattr(exc, "reason", str(exc))
        if "No such file" in reason:
            reason = f"no such file: {rel[:200]!r} (looked for {str(base / rel)[:300]})"
        elif reason.startswith("cannot read"):
            reason = f"cannot use the path {rel[:80]!r}: {reason.rsplit(': ', 1)[-1]}"
        raise c.error(key, reason) from None
    if suffixes and p.suffix.lower() not in suffixes:
        raise c.error(key, f"expected a {' / '.join(suffixes)} file, got {rel[:200]!r}")
    return p


def _refuse_allow_paths(top: SceneTable) -> None:
    """A file never widens its own confinement: the old ``allow_paths`` key is an error that says
    what to do instead (issue 24)."""
    if "allow_paths" in top.table:
        raise top.error("allow_paths", "a scene file cannot allow itself to read outside its folder: name the "
                                       "folders on the command line (--allow-path DIR, repeatable) or in the "
                                       "PISTE_ALLOW_PATHS environment variable instead")


# ----------------------------------------------------------------------------- the sections
def _parse_terrain(t: SceneTable, scene: SceneFile) -> TerrainSpec:
    path, base = t.path, t.base
    t.allow({"source", "seed", "spacing", "height_scale", "height_offset", "key", "samples_per_patch", "smooth",
             "nodata", "vertical_units", "tiles", "tile_patches", "ssx_pbd"})
    source = t.get("source", "str", "default")
    ts = TerrainSpec(seed=t.get("seed", "int", 0), height_scale=t.get("height_scale", "float", 1.0),
                     height_offset=t.get("height_offset", "float", 0.0), key=t.get("key", "str"),
                     samples_per_patch=t.get("samples_per_patch", "int", 4), smooth=t.get("smooth", "bool", False))
    if "spacing" in t.table:
        sp = t.table["spacing"]
        ts.spacing = (t.get("spacing", "pos"),) * 2 if not isinstance(sp, list) else t.get("spacing", "vec2")
        if min(ts.spacing) <= 0:
            raise t.error("spacing", f"expected spacing > 0, got {sp!r}")
    if ts.samples_per_patch < 3:
        raise t.error("samples_per_patch", f"expected at least 3, got {ts.samples_per_patch}")
    _bounded(t, "samples_per_patch", ts.samples_per_patch, 3, 256, "samples a patch side")
    _bounded(t, "seed", ts.seed, 0, MAX_SEED, "a seed")
    _bounded(t, "spacing", ts.spacing, 1e-3, 1e5, "metres between samples")
    _bounded(t, "height_scale", ts.height_scale, -1e6, 1e6, "a scale")
    _bounded(t, "height_offset", ts.height_offset, -MAX_SCENE_COORDINATE, MAX_SCENE_COORDINATE, "metres")
    _large_world_keys(t, ts, base)
    if "ssx_pbd" in t.table:  # an SSX Tricky level, its .ssh / _L.ssh beside it (piste.pipeline.ssx_level)
        if source != "default":
            raise t.error("ssx_pbd", "give the terrain as source or as ssx_pbd, not both")
        ts.path, ts.kind = _file(t, "ssx_pbd", base, (".pbd",)), "ssx_pbd"
    elif source != "default":
        ts.path = _file(t, "source", base)
        suf = ts.path.suffix.lower()
        if suf == ".bpt":
            ts.kind = "bpt"
        elif suf == ".pbd":
            ts.kind = "ssx_pbd"
        elif suf in (".tif", ".tiff") and _tiff_is_geotiff(ts.path):
            ts.kind = "geotiff"
        elif suf in HEIGHTFIELD_IMAGES:
            ts.kind = "heightfield"
        elif suf == ".npz":
            ts.kind = "net" if _npz_is_net(ts.path) else "heightfield"
        else:
            raise t.error("source", f"expected \"default\", a .bpt, an .npz or a height-field image "
                                    f"({', '.join(HEIGHTFIELD_IMAGES)}), got {source!r}")
        if ts.kind == "heightfield" and ts.spacing is None and suf != ".npz":
            raise SceneError(path, "a height-field image needs 'spacing' (metres between samples)",
                             line=t.line(), key="terrain.spacing")
    return ts


def _parse_lightmap(lm: SceneTable, scene: SceneFile) -> LightmapSpec:
    lm.allow({"res", "shadows", "gutter", "bounces", "sun_radius"})
    spec = LightmapSpec(lm.get("res", "int", 8), lm.get("shadows", "bool", True), lm.get("gutter", "int", 1),
                        lm.get("bounces", "int", 0), lm.get("sun_radius", "float", 0.0))
    if not 0 <= spec.bounces <= 16:
        raise lm.error("bounces", f"expected 0 <= bounces <= 16, got {spec.bounces}")
    if not 0.0 <= spec.sun_radius <= 10.0:
        raise lm.error("sun_radius", f"expected 0 <= sun_radius <= 10 degrees, got {spec.sun_radius}")
    if not 2 <= spec.res <= 64:
        raise lm.error("res", f"expected 2 <= res <= 64 texels, got {spec.res}")
    if not 0 <= spec.gutter <= 4:
        raise lm.error("gutter", f"expected 0 <= gutter <= 4, got {spec.gutter}")
    return spec


def _parse_lod(lo: SceneTable, scene: SceneFile) -> LodSpec:
    lo.allow({"near", "far", "character", "ratios", "morph", "preset", "character_pixels"})
    preset = lo.get("preset", "str", "ssx_tricky" if scene.terrain.kind == "ssx_pbd" else "piste")
    if preset not in LOD_PRESETS:
        raise lo.error("preset", f"expected one of {', '.join(map(repr, LOD_PRESETS))}, got {preset!r}")
    spec = LodSpec(lo.get("near", "float", LOD_PRESETS[preset][0]), lo.get("far", "float", LOD_PRESETS[preset][1]),
                   lo.get("character", "vec2", (14.0, 35.0)), lo.get("ratios", "floats", (1.0, 0.5, 0.25)),
                   lo.get("morph", "bool", True), lo.get("character_pixels", "float", 1.0))
    _bounded(lo, "character_pixels", spec.character_pixels, 0.0, 64.0, "pixels")
    if not 0 <= spec.near <= spec.far:
        raise lo.error("far", f"expected 0 <= near <= far, got near={spec.near}, far={spec.far}")
    _bounded(lo, "far", spec.far, 0.0, MAX_FAR, "metres")
    _bounded(lo, "character", spec.character, 0.0, 1e5, "metres")
    if not all(0 < r <= 1 for r in spec.ratios):
        raise lo.error("ratios", f"expected ratios in (0, 1], got {list(spec.ratios)}")
    return spec


def _parse_visibility(vi: SceneTable, scene: SceneFile) -> VisibilitySpec:
    vi.allow({"enabled", "cell", "eye_heights", "method"})
    spec = VisibilitySpec(vi.get("enabled", "bool", True), vi.get("cell", "pos", 50.0),
                          vi.get("eye_heights", "floats", (1.7, 9.0)), vi.get("method", "str", "auto"))
    _bounded(vi, "cell", spec.cell, 1.0, 1e5, "metres")
    _bounded(vi, "eye_heights", spec.eye_heights, -1e4, 1e4, "metres")
    if spec.method not in ("auto", "horizon", "rays"):
        raise vi.error("method", f"expected \"auto\", \"horizon\" or \"rays\", got {spec.method!r}")
    return spec


def _parse_render(re_: SceneTable, scene: SceneFile) -> RenderSpec:
    re_.allow({"size", "lightmap_mode", "fog", "face", "object_lod", "aa", "dof", "soft_shadows", "occlusion"})
    size = re_.get("size", "vec2", (640, 448))
    if not all(float(s).is_integer() and 16 <= s <= 8192 for s in size):
        raise re_.error("size", f"expected [width, height], whole pixels in 16..8192, got {list(size)}")
    spec = RenderSpec((int(size[0]), int(size[1])), re_.get("lightmap_mode", "str", "modulate"))
    if spec.lightmap_mode not in ("modulate", "ps2"):
        raise re_.error("lightmap_mode", f"expected \"modulate\" or \"ps2\", got {spec.lightmap_mode!r}")
    fog = re_.table.get("fog", "auto")
    if fog != "auto":
        fog = re_.get("fog", "float") if not isinstance(fog, str) else None
        if fog is None or fog < 0:
            raise re_.error("fog", f"expected a density per metre >= 0 or \"auto\", got {re_.table['fog']!r}")
    spec.fog = _bounded(re_, "fog", fog if fog != "auto" else None, 0.0, 10.0, "a density per metre") or fog
    spec.face = re_.get("face", "str", "morph")
    if spec.face not in ("morph", "null_bones", "off"):
        raise re_.error("face", f"expected \"morph\", \"null_bones\" or \"off\", got {spec.face!r}")
    spec.object_lod = re_.get("object_lod", "float", DEFAULT_LOD_PIXELS)
    if not 0.0 <= spec.object_lod <= 64.0:
        raise re_.error("object_lod", f"expected pixels in 0..64 (0: full meshes), got {spec.object_lod!r}")
    spec.aa = re_.get("aa", "str", "off")
    if spec.aa not in ("off", "msaa2", "msaa4", "msaa8", "fxaa"):
        raise re_.error("aa", f"expected \"off\", \"msaa2\", \"msaa4\", \"msaa8\" or \"fxaa\", got {spec.aa!r}")
    if "dof" in re_.table:
        dof = re_.get("dof", "vec2")
        if not (0.0 < dof[0] <= 1e5 and 0.0 <= dof[1] <= 100.0):
            raise re_.error("dof", f"expected [focus, aperture]: a focus distance in (0, 100000] m and a lens radius "
                                   f"in [0, 100] m, got {list(dof)}")
        spec.dof = [float(dof[0]), float(dof[1])]
    spec.soft_shadows = re_.get("soft_shadows", "bool", False)
    spec.occlusion = re_.get("occlusion", "bool", False)
    return spec


# the default course's riders following the track and objects placed along it
def _parse_pack(pk: SceneTable, scene: SceneFile) -> PackSpec:
    pk.allow({"follow", "start"})
    follow = pk.get("follow", "str", "track")
    if follow != "track":
        raise pk.error("follow", f"expected \"track\", got {follow!r}")
    start = pk.get("start", "float", 0.12)
    if not 0.0 <= start <= 1.0:
        raise pk.error("start", f"expected a fraction of the track in [0, 1], got {start}")
    if scene.terrain.kind != "default":
        raise pk.error("follow", "riders following the track need the default course (terrain.source = \"default\")")
    return PackSpec(follow=follow, start=start)


def _check_pack(pk: SceneTable, scene: SceneFile) -> None:
    if scene.pack and scene.riders:
        raise pk.error(None, "give riders as [pack] (following the track) or as [[riders]], not both")


def _parse_auto_objects(ao: SceneTable, scene: SceneFile) -> AutoObjectsSpec:
    ao.allow({"seed", *AUTO_OBJECT_COUNTS})
    seed = _bounded(ao, "seed", ao.get("seed", "int", 0), 0, MAX_SEED, "a seed")
    counts: dict[str, int] = {}
    for k, d in AUTO_OBJECT_COUNTS.items():
        counts[k] = ao.get(k, "int", d)
        if not 0 <= counts[k] <= 10_000:
            raise ao.error(k, f"expected 0 <= {k} <= 10000, got {counts[k]}")
    if scene.terrain.kind != "default":
        raise ao.error("seed", "objects placed along the track need the default course (terrain.source = \"default\")")
    return AutoObjectsSpec(seed=seed, **counts)


def _check_auto_objects(ao: SceneTable, scene: SceneFile) -> None:
    if scene.auto_objects and scene.objects:
        raise ao.error(None, "give objects as [auto_objects] or as [[objects]], not both")


def _parse_tile_objects(items: list[SceneTable], scene: SceneFile) -> list[TileObjectSpec]:
    rules = []
    for c in items:  # rules for piste.pipeline.tile_objects.ObjectRule
        c.allow({"kind", "density", "slope", "altitude", "scale"})
        kind = c.get("kind", "str", required=True)
        if kind not in TILE_OBJECT_KINDS:
            raise c.error("kind", f"expected one of {', '.join(TILE_OBJECT_KINDS)}, got {kind!r}")
        if scene.terrain.kind not in ("heightfield", "geotiff"):
            raise c.error("kind", "objects placed on tiles need a tiled height-field terrain (GeoTIFF, PNG or .npz), "
                                  f"got terrain kind {scene.terrain.kind!r}")
        rule: dict[str, Any] = {"kind": kind, "density": _bounded(c, "density", c.get("density", "pos", required=True),
                                                                  0.0, 1e4, "candidates a hectare")}
        for key, lo, hi, default, what in (("slope", 0.0, 90.0, (0.0, 90.0), "degrees"),
                                           ("altitude", -1e6, 1e6, None, "metres"),
                                           ("scale", 1e-3, 1e3, (0.7, 1.4), "a size")):
            v = _bounded(c, key, c.get(key, "vec2", default), lo, hi, what)
            if v is not None and v[0] > v[1]:
                raise c.error(key, f"expected [min, max] with min <= max, got {list(v)}")
            if v is not None:
                rule[key] = v
        rules.append(TileObjectSpec(**rule))
    return rules


def _parse_gltf(items: list[SceneTable], scene: SceneFile) -> list[GltfSpec]:
    out = []
    for g in items:
        g.allow({"file", "lights", "cameras", "offset", "scale", "up", "white"})
        spec = GltfSpec(_file(g, "file", g.base, (".gltf", ".glb")), g.get("lights", "bool", True),
                        g.get("cameras", "bool", True), g.get("offset", "vec3", (0.0, 0.0, 0.0)),
                        g.get("scale", "pos", 1.0), g.get("up", "str", "y"), g.get("white", "pos", 683.0),
                        scene.allow_paths)
        if spec.up not in ("y", "z"):
            raise g.error("up", f"expected \"y\" or \"z\", got {spec.up!r}")
        _bounded(g, "offset", spec.offset, -MAX_SCENE_COORDINATE, MAX_SCENE_COORDINATE, "metres")
        _bounded(g, "scale", spec.scale, 1e-6, 1e6, "a scale")
        _bounded(g, "white", spec.white, 1e-6, 1e9, "lumens")
        out.append(spec)
    return out


def _parse_actors(kind: str, items: list[SceneTable], scene: SceneFile) -> list[ActorSpec]:
    """[[riders]] or [[objects]]: names unique across both (riders are parsed first)."""
    names = {a.name for a in scene.riders} if kind == "objects" else set()
    out = []
    for i, a in enumerate(items):
        base = a.base
        keys = {"name", "model", "position", "heading", "scale"} | (
            {"clip", "phase", "clips_from", "bone_map", "texture"} if kind == "riders" else set())
        a.allow(keys)
        default_model = "builtin:rider" if kind == "riders" else None
        model = a.get("model", "str", default_model, required=default_model is None)
        if model.startswith("builtin:"):
            allowed = ("builtin:rider",) if kind == "riders" else tuple(m for m in BUILTIN_MODELS if m != "builtin:rider")
            if model not in allowed:
                raise a.error("model", f"unknown built-in model {model!r}: expected one of {', '.join(allowed)} "
                                       "or a .gltf/.glb file")
        elif model.startswith("ssx:") and kind == "riders":  # an SSX Tricky .mpf (piste.pipeline.ssx_rider)
            model = str(_file(a, "model", base, (".mpf",), value=model[4:]))
        else:
            model = str(_file(a, "model", base, (".gltf", ".glb")))
        name = a.get("name", "str", f"{kind[:-1]}{i}")
        _bounded(a, "position", a.get("position", "vec23", required=True), -MAX_SCENE_COORDINATE,
                 MAX_SCENE_COORDINATE, "metres")
        _bounded(a, "heading", a.get("heading", "float", 0.0), -1e6, 1e6, "degrees")
        _bounded(a, "phase", a.get("phase", "float", 0.0), -1e6, 1e6, "seconds")
        _bounded(a, "scale", a.get("scale", "pos", 1.0), 1e-6, 1e6, "a scale")
        if name in names:
            raise a.error("name", f"duplicate name {name!r}")
        names.add(name)
        spec = ActorSpec(name, model, a.get("position", "vec23", required=True), a.get("heading", "float", 0.0),
                         a.get("clip", "str"), a.get("phase", "float", 0.0), a.get("scale", "pos", 1.0), a.line())
        cf = a.table.get("clips_from")
        if isinstance(cf, str) and cf.lower().endswith(".afl"):  # an SSX Tricky bank (piste.formats.ssx.afl)
            if not model.lower().endswith(".mpf"):
                raise a.error("clips_from", "an .afl animation bank plays only on an ssx:<RIDER.mpf> model")
            if "bone_map" in a.table:
                raise a.error("bone_map", "an .afl bank drives the .mpf's body bones in file order: no bone_map")
            spec.clips_from = str(_file(a, "clips_from", base, (".afl",)))
        elif "clips_from" in a.table:
            spec.clips_from = str(_file(a, "clips_from", base, (".gltf", ".glb") + (
                (".afl",) if model.lower().endswith(".mpf") else ())))
            bm = a.table.get("bone_map", "builtin")
            if not (bm == "builtin" or (isinstance(bm, dict) and all(
                    isinstance(k, str) and isinstance(v, str) for k, v in bm.items()))):
                raise a.error("bone_map", f"expected \"builtin\" or a table of clip bone = \"model bone\", got {bm!r}")
            spec.bone_map = bm
        elif "bone_map" in a.table:
            raise a.error("bone_map", "needs clips_from = \"<a .gltf/.glb with the clips>\"")
        if "texture" in a.table:  # an SSX texture bank for an ssx: rider (piste.pipeline.ssx_rider)
            if not model.lower().endswith(".mpf"):
                raise a.error("texture", "only an ssx:<RIDER.mpf> model takes a texture bank (.ssh)")
            spec.texture = str(_file(a, "texture", base, (".ssh",)))
        out.append(spec)
    return out


def _parse_riders(items: list[SceneTable], scene: SceneFile) -> list[ActorSpec]:
    return _parse_actors("riders", items, scene)


def _parse_objects(items: list[SceneTable], scene: SceneFile) -> list[ActorSpec]:
    return _parse_actors("objects", items, scene)


def _parse_lights(items: list[SceneTable], scene: SceneFile) -> tuple[_Light, ...]:
    return tuple(_light(c) for c in items)


def _parse_cameras(items: list[SceneTable], scene: SceneFile) -> list[CameraSpec]:
    out: list[CameraSpec] = []
    cam_names = set()
    for i, c in enumerate(items):
        c.allow({"name", "eye", "target", "up", "fov", "near", "far", "track", "height"})
        cs = CameraSpec(c.get("name", "str", f"camera{i}"), c.get("eye", "vec3"), c.get("target", "vec3"),
                        c.get("up", "vec3", (0.0, 0.0, 1.0)), c.get("fov", "float", 60.0), c.get("near", "pos"),
                        c.get("far", "pos"), c.get("track", "vec2"), c.get("height", "float", 9.0))
        if cs.name in cam_names:
            raise c.error("name", f"duplicate camera name {cs.name!r}")
        cam_names.add(cs.name)
        if cs.track is None and (cs.eye is None or cs.target is None):
            raise c.error("eye" if cs.eye is None else "target", "a camera needs eye and target, or track = [from, to]")
        if cs.track is not None and not all(0.0 <= x <= 1.0 for x in cs.track):
            raise c.error("track", f"expected fractions of the track in [0, 1], got {list(cs.track)}")
        if cs.track is not None and scene.terrain.kind != "default":
            raise c.error("track", "track cameras need the default course (terrain.source = \"default\")")
        if not 0 < cs.fov < 180:
            raise c.error("fov", f"expected 0 < fov < 180 degrees, got {cs.fov}")
        for k in ("eye", "target"):
            _bounded(c, k, getattr(cs, k), -MAX_SCENE_COORDINATE, MAX_SCENE_COORDINATE, "metres")
        _bounded(c, "height", cs.height, 0.0, 1e5, "metres above the track")
        _bounded(c, "near", cs.near, MIN_NEAR, MAX_FAR / 10, "metres")
        _bounded(c, "far", cs.far, MIN_NEAR, MAX_FAR, "metres")
        if cs.near is not None and cs.far is not None:
            if not cs.near < cs.far:
                raise c.error("far", f"expected near < far, got near={cs.near}, far={cs.far}")
            if cs.far / cs.near > MAX_FAR_NEAR_RATIO:
                raise c.error("far", f"expected far / near <= {MAX_FAR_NEAR_RATIO:g} (depth precision), got "
                                     f"near={cs.near}, far={cs.far} (ratio {cs.far / cs.near:.3g})")
        if cs.eye is not None and cs.target is not None and cs.eye == cs.target:
            raise c.error("target", "eye and target are the same point")
        out.append(cs)
    return out


# ----------------------------------------------------------------------------- the section registry
@dataclass(frozen=True)
class SceneSection:
    """One top-level section of a scene file and how it is read.

    ``name`` is the TOML key (``[name]`` or, with ``array=True``, ``[[name]]``).  ``parse(table,
    scene)`` gets a :class:`SceneTable` (a list of them for an array; every key checked with
    ``table.allow`` / ``table.get``, errors from ``table.error`` name the file, line and key) and
    the scene parsed so far (sections earlier in :data:`SCENE_SECTIONS`: ``scene.terrain`` is
    known to every later one), and returns the typed value: it becomes ``scene.<name>`` when
    :class:`SceneFile` has that field, else ``scene.sections[name]``.  ``only_if_given``: parse it
    only when the file has the section (else the field keeps its default).  ``check(table,
    scene)`` runs once every section is parsed (rules across sections: ``[pack]`` or
    ``[[riders]]``, not both).
    """

    name: str
    parse: Callable[[Any, SceneFile], Any]
    array: bool = False
    only_if_given: bool = False
    check: Callable[[SceneTable, SceneFile], None] | None = None


#: the sections a scene file may have, parsed in this order (add one with :func:`register_section`);
#: besides these the top level takes ``name`` (and refuses ``allow_paths``, naming what to do instead)
SCENE_SECTIONS: dict[str, SceneSection] = {s.name: s for s in (
    SceneSection("terrain", _parse_terrain),
    SceneSection("lightmap", _parse_lightmap),
    SceneSection("lod", _parse_lod),
    SceneSection("visibility", _parse_visibility),
    SceneSection("render", _parse_render),
    SceneSection("pack", _parse_pack, only_if_given=True, check=_check_pack),
    SceneSection("auto_objects", _parse_auto_objects, only_if_given=True, check=_check_auto_objects),
    SceneSection("tile_objects", _parse_tile_objects, array=True),
    SceneSection("gltf", _parse_gltf, array=True),
    SceneSection("riders", _parse_riders, array=True),
    SceneSection("objects", _parse_objects, array=True),
    SceneSection("lights", _parse_lights, array=True),
    SceneSection("cameras", _parse_cameras, array=True),
)}
#: top-level keys that are not sections
_TOP_KEYS = ("name", "allow_paths")
#: SceneFile fields no section may set
_RESERVED = frozenset({*_TOP_KEYS, "path", "text", "sections"})


def register_section(section: SceneSection, *, after: str | None = None) -> SceneSection:
    """Add ``section`` to :data:`SCENE_SECTIONS`, parsed after section ``after`` (default: last).
    Returns ``section``."""
    if section.name in SCENE_SECTIONS or section.name in _RESERVED:
        raise ConfigError(f"scene section {section.name!r} is registered already (or a reserved name: "
                          f"{', '.join(sorted(_RESERVED))})")
    if after is not None and after not in SCENE_SECTIONS:
        raise ConfigError(f"no scene section {after!r} to place {section.name!r} after: sections are "
                          f"{', '.join(SCENE_SECTIONS)}")
    items = list(SCENE_SECTIONS.values())
    i = [s.name for s in items].index(after) + 1 if after is not None else len(items)
    items.insert(i, section)
    SCENE_SECTIONS.clear()
    SCENE_SECTIONS.update((s.name, s) for s in items)
    return section


def unregister_section(name: str) -> SceneSection:
    """Remove the section called ``name`` from :data:`SCENE_SECTIONS` (and return it)."""
    if name not in SCENE_SECTIONS:
        raise ConfigError(f"no scene section {name!r}: sections are {', '.join(SCENE_SECTIONS)}")
    return SCENE_SECTIONS.pop(name)


_SCENE_FIELDS = frozenset(f.name for f in fields(SceneFile))


def loads_scene(text: str, path: str | os.PathLike[str] = "scene.toml") -> SceneFile:
    """Parse and validate scene TOML ``text``; relative paths resolve against ``path``'s folder."""
    path = Path(path)
    doc = loads_toml(text, path, "scene file", SceneError)
    lines = key_lines(text)
    top = SceneTable(path, lines, doc, (), "")
    top.allow({*_TOP_KEYS, *SCENE_SECTIONS})
    scene = SceneFile(path=path, name=top.get("name", "str", path.stem), text=text)
    _refuse_allow_paths(top)
    scene.allow_paths = user_allow_paths()
    read: list[tuple[SceneSection, SceneTable]] = []
    for section in list(SCENE_SECTIONS.values()):
        if section.only_if_given and section.name not in top.table:
            continue
        given: Any = _array(top, section.name) if section.array else _table(top, section.name)
        value = section.parse(given, scene)
        if section.name in _SCENE_FIELDS:
            setattr(scene, section.name, value)
        else:
            scene.sections[section.name] = value
        if section.check is not None:  # an array's rules across sections name the array
            read.append((section, SceneTable(path, lines, {}, (section.name,), section.name) if section.array else given))
    for section, table in read:
        assert section.check is not None
        section.check(table, scene)
    return scene


def _light(c: SceneTable) -> _Light:
    kinds: dict[str, type[_Light]] = {"ambient": AmbientLight, "directional": DirectionalLight, "point": PointLight,
                                      "spot": SpotLight}
    kind = c.get("type", "str", required=True)
    if kind not in kinds:
        raise c.error("type", f"unknown light type {kind!r}: expected one of {', '.join(kinds)}")
    cls = kinds[kind]
    allowed = {f.name for f in fields(cls)}
    c.allow(allowed | {"type"})
    kw: dict[str, Any] = {}
    for f in fields(cls):
        if f.name not in c.table:
            continue
        kind_of = {"color": "vec3", "direction": "vec3", "position": "vec3", "shadows": "bool", "name": "str"}.get(f.name)
        if f.name == "range" and c.table[f.name] == math.inf:
            kw[f.name] = math.inf
            continue
        kw[f.name] = c.get(f.name, kind_of or "float")
    for need in ("direction", "position"):
        if need in allowed and need not in kw:
            raise SceneError(c.path, f"a {kind} light needs {need!r}", line=c.line(), key=c.name(need))
    try:
        return cls(**kw)
    except ValidationError as exc:
        msg = str(exc)
        bad = next((k for k in kw if re.search(rf"\b{k}\b", msg)), None)
        raise c.error(bad, msg) from None


def _large_world_keys(t: SceneTable, ts: TerrainSpec, base: Path) -> None:
    """terrain.nodata / vertical_units (GeoTIFF) and tiles / tile_patches (tiled nets)."""
    if "nodata" in t.table:
        v = t.table["nodata"]
        ts.nodata = t.get("nodata", "float") if not isinstance(v, str) else t.get("nodata", "str")
        if isinstance(ts.nodata, str) and ts.nodata not in ("nearest", "error"):
            raise t.error("nodata", f"expected \"nearest\", \"error\" or a number, got {v!r}")
    ts.vertical_units = t.get("vertical_units", "str")
    if ts.vertical_units is not None and ts.vertical_units not in ("metre", "meter", "foot", "us_survey_foot"):
        raise t.error("vertical_units", f"expected metre, foot or us_survey_foot, got {ts.vertical_units!r}")
    if "tiles" in t.table:
        try:  # an output folder (built later) or a world to read: confined like every path
            ts.tiles = confined_folder(t.path, t.get("tiles", "str"), field=t.name("tiles"))
        except PisteError as exc:
            raise t.error("tiles", getattr(exc, "reason", str(exc))) from None
    ts.tile_patches = t.get("tile_patches", "int", 64)
    if not 2 <= ts.tile_patches <= 1024:
        raise t.error("tile_patches", f"expected 2 .. 1024 patches a tile side, got {ts.tile_patches}")


def _tiff_is_geotiff(path: Path) -> bool:
    """A TIFF with georeferencing tags (ModelPixelScale or ModelTransformation)."""
    try:
        import tifffile
    except ImportError:
        return False
    try:
        with open_file(path) as fh, tifffile.TiffFile(fh) as tf:
            tags = tf.pages[0].tags  # type: ignore[union-attr]  # the first page is a TiffPage
            return 33550 in tags or 34264 in tags
    except Exception:
        return False


def _npz_is_net(path: Path) -> bool:
    import numpy as np

    try:
        with open_file(path) as fh, np.load(fh, allow_pickle=False) as data:
            return "control_points" in data.files
    except Exception:
        return False


def load_scene(path: str | os.PathLike[str]) -> SceneFile:
    """Read and validate the scene file at ``path`` (see the module docstring)."""
    path = Path(path)
    try:  # regular files only, opened without blocking (a pipe or device is refused, never read)
        data = read_regular(path, MAX_TOML_BYTES, what="scene file")
    except PisteError as exc:
        reason = getattr(exc, "reason", str(exc))
        if "No such file" in reason:
            reason = "no such file"
        elif "folder" in reason:
            reason = "is a folder, expected a scene .toml file"
        elif "regular file" in reason:
            reason = "not a regular file, expected a scene .toml file"
        raise SceneError(path, reason) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(path, f"not UTF-8 text ({exc.reason})") from None
    return loads_scene(text, path)
