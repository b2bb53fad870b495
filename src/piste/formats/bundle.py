"""The ``.piste`` bundle: everything ``piste build`` pre-processed for a scene, in one file.

Layout: a zip archive with

* ``manifest.json`` -- ``{"format": "piste.bundle/1", ...}``: the scene's name, lights, cameras,
  riders, objects, settings, and a ``members`` table (shape, dtype and SHA-256 of each array);
* one ``.npy`` member per array, named by path (``terrain/control_points.npy``,
  ``lightmap/atlas.npy``, ``visibility/patch_bits.npy``, ``characters/<model>/lod0/strips.npy``, ...).

Members are sorted, every timestamp is 1980-01-01 and arrays are written with fixed headers, so the
same content gives the same bytes.  The file is written atomically (temp file + rename).

:func:`load_bundle` checks the format version and every member (zip CRC, shape, dtype, and the
manifest's SHA-256) and raises :class:`~piste.errors.FormatError` naming the file and member on a
wrong version or a corrupt file.  The terrain net, light map, lights, cameras and visibility are
built on load; objects and characters when first asked for.

API
---
BUNDLE_FORMAT                         "piste.bundle/1"
write_bundle(path, manifest, arrays)  atomic, deterministic
load_bundle(path) -> Bundle
read_manifest(path) -> dict           the manifest only (cheap)
Bundle                                ``.net``, ``.lightmap``, ``.lights``, ``.cameras``, ``.visibility``,
                                      ``.objects()``, ``.rider_model()``, ``.arrays``, ``.manifest``
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from piste.errors import FormatError

__all__ = ["BUNDLE_FORMAT", "write_bundle", "load_bundle", "read_manifest", "Bundle", "lights_from_dict",
           "camera_to_dict", "camera_from_dict"]

BUNDLE_FORMAT = "piste.bundle/1"
_EPOCH = (1980, 1, 1, 0, 0, 0)


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
    return buf.getvalue()


def write_bundle(path, manifest: dict, arrays: dict, compresslevel: int = 1) -> Path:
    """Write a bundle atomically: ``manifest`` (JSON-able dict; ``format`` and ``members`` are set
    here) and ``arrays`` (``{"a/b": ndarray}``, stored as ``a/b.npy``).  Returns the path."""
    from piste.formats.atomic import atomic_path

    man = dict(manifest)
    man["format"] = BUNDLE_FORMAT
    blobs = {}
    members = {}
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        if a.dtype == object:
            raise FormatError(path, "object arrays cannot be stored", field=name)
        data = _npy_bytes(a)
        blobs[f"{name}.npy"] = data
        members[name] = {"shape": list(a.shape), "dtype": a.dtype.str, "sha256": hashlib.sha256(data).hexdigest()}
    man["members"] = members
    text = (json.dumps(man, indent=1, sort_keys=True, allow_nan=False) + "\n").encode()
    path = Path(path)
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=compresslevel) as zf:
            entries = [("manifest.json", text)] + sorted(blobs.items())
            for name, data in entries:
                info = zipfile.ZipInfo(name, date_time=_EPOCH)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                info.create_system = 3
                zf.writestr(info, data, compresslevel=compresslevel)
    return path


def _open(path: Path) -> zipfile.ZipFile:
    try:
        return zipfile.ZipFile(path)
    except FileNotFoundError:
        raise FormatError(path, "no such file") from None
    except IsADirectoryError:
        raise FormatError(path, "is a folder, expected a .piste bundle") from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise FormatError(path, f"not a piste bundle (not a zip archive: {exc})") from None


def _manifest(path: Path, zf: zipfile.ZipFile) -> dict:
    try:
        raw = zf.read("manifest.json")
    except KeyError:
        raise FormatError(path, "not a piste bundle: no manifest.json member", field="manifest.json") from None
    except (zipfile.BadZipFile, zlib.error, OSError) as exc:
        raise FormatError(path, f"corrupt member ({exc})", field="manifest.json") from None
    try:
        man = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(path, f"manifest is not valid JSON ({exc})", field="manifest.json") from None
    if not isinstance(man, dict):
        raise FormatError(path, "manifest must be a JSON object", field="manifest.json")
    fmt = man.get("format")
    if fmt != BUNDLE_FORMAT:
        raise FormatError(path, f"bundle format {fmt!r}, this piste reads {BUNDLE_FORMAT!r}: rebuild it with "
                                "`piste build`", field="format")
    if not isinstance(man.get("members"), dict):
        raise FormatError(path, "manifest has no 'members' table", field="members")
    return man


def read_manifest(path) -> dict:
    """The manifest of the bundle at ``path`` (version-checked)."""
    path = Path(path)
    with _open(path) as zf:
        return _manifest(path, zf)


def _read_arrays(path: Path, zf: zipfile.ZipFile, members: dict, verify: bool) -> dict:
    out = {}
    names = set(zf.namelist())
    for name, info in members.items():
        member = f"{name}.npy"
        if member not in names:
            raise FormatError(path, "member listed in the manifest is missing", field=member)
        try:
            data = zf.read(member)
        except (zipfile.BadZipFile, zlib.error, OSError) as exc:
            raise FormatError(path, f"corrupt member ({exc})", field=member) from None
        if verify and hashlib.sha256(data).hexdigest() != info.get("sha256"):
            raise FormatError(path, "checksum mismatch (the file is corrupt)", field=member)
        try:
            a = np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
        except Exception as exc:
            raise FormatError(path, f"not a valid .npy array ({exc})", field=member) from None
        if list(a.shape) != list(info.get("shape", [])) or a.dtype.str != info.get("dtype"):
            raise FormatError(path, f"expected shape {info.get('shape')} dtype {info.get('dtype')}, got "
                                    f"{list(a.shape)} {a.dtype.str}", field=member)
        out[name] = a
    return out


# ----------------------------------------------------------------------------- helpers
def lights_from_dict(d: dict):
    """:class:`piste.lighting.Lights` from ``Lights.to_dict()`` output (infinite ranges may be
    the string "inf")."""
    from piste.lighting.lights import AmbientLight, DirectionalLight, Lights, PointLight, SpotLight

    kinds = {"ambient": AmbientLight, "directional": DirectionalLight, "point": PointLight, "spot": SpotLight}
    out = []
    for kind, items in d.items():
        for item in items:
            kw = dict(item)
            if isinstance(kw.get("range"), str):
                kw["range"] = float(kw["range"])
            out.append(kinds[kind](**kw))
    return Lights(tuple(out))


def camera_to_dict(cam) -> dict:
    return {"eye": [float(x) for x in cam.eye], "target": [float(x) for x in cam.target], "up": [float(x) for x in cam.up],
            "fov_y": float(cam.fov_y), "near": float(cam.near), "far": float(cam.far),
            "ortho_height": None if cam.ortho_height is None else float(cam.ortho_height)}


def camera_from_dict(d: dict):
    from piste.world.camera import Camera

    return Camera(np.array(d["eye"]), np.array(d["target"]), up=np.array(d["up"]), fov_y=d["fov_y"], near=d["near"],
                  far=d["far"], ortho_height=d.get("ortho_height"))


# ----------------------------------------------------------------------------- the bundle
@dataclass
class Bundle:
    """A loaded bundle.

    Attributes
    ----------
    path : Path;  manifest : dict;  arrays : {name: ndarray}
    net : piste.terrain.PatchNet (light-map rects set);  lightmap : piste.lighting.LightMap
    lights : piste.lighting.Lights;  cameras : {name: piste.world.camera.Camera} (in scene order)
    visibility : piste.pipeline.visibility.Visibility or None
    centerline : (k, 3) track centre line (the default course) or None
    """

    path: Path
    manifest: dict
    arrays: dict
    net: object
    lightmap: object
    lights: object
    cameras: dict
    visibility: object = None
    centerline: np.ndarray | None = None
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def name(self) -> str:
        return str(self.manifest.get("name", self.path.stem))

    def camera(self, name: str | None = None):
        """The camera called ``name`` (default: the first)."""
        from piste.errors import ConfigError

        if not self.cameras:
            raise ConfigError(f"{self.path}: the scene has no cameras")
        if name is None:
            return next(iter(self.cameras.values()))
        if name not in self.cameras:
            raise ConfigError(f"{self.path}: no camera {name!r}; the scene has {', '.join(self.cameras)}")
        return self.cameras[name]

    def objects(self):
        """The placed objects as a :class:`piste.world.objects.ObjectSet` (None when there are none)."""
        if "objects" in self._cache:
            return self._cache["objects"]
        info = self.manifest.get("objects") or {}
        kinds = tuple(info.get("kinds", ()))
        if not kinds:
            self._cache["objects"] = None
            return None
        from piste.world.objects import CompressedMesh, ObjectSet, normal_matrix

        a = self.arrays
        meshes = {}
        for k in kinds:
            p = f"objects/meshes/{k}/"
            m = info["meshes"][k]
            meshes[k] = CompressedMesh(k, a[p + "positions"], a[p + "pos_offset"], a[p + "pos_extent"], a[p + "uv"],
                                       a[p + "uv_offset"], a[p + "uv_extent"], a[p + "normals"], int(m["normal_bits"]),
                                       a[p + "indices"], float(m["radius"]))
        kind = a["objects/kind"].astype(np.int64)
        matrix = a["objects/matrix"].astype(np.float64)
        vl = None
        if len(self.lights.direct) or len(self.lights.ambient):
            from piste.lighting.vertex import choose_lights_many

            vl = choose_lights_many(self.lights, a["objects/center"])
        tex = a.get("objects/texture")
        counts = {k: int(np.count_nonzero(kind == i)) for i, k in enumerate(kinds)}
        objs = ObjectSet(meshes, kinds, kind, matrix, normal_matrix(matrix), a["objects/center"].astype(np.float64),
                         a["objects/radius"].astype(np.float64), vl, tex, counts)
        self._cache["objects"] = objs
        return objs

    def vertex_colors(self) -> dict:
        """Baked per-instance vertex colours ``{kind: (k, v, 3) uint8}`` half-bright."""
        info = self.manifest.get("objects") or {}
        return {k: self.arrays[f"objects/colors/{k}"] for k in info.get("kinds", ())}

    def rider_model(self):
        """The riders' character :class:`piste.character.Model` (skeleton, LOD-0 mesh, clips) or None."""
        if "rider_model" in self._cache:
            return self._cache["rider_model"]
        info = self.manifest.get("characters") or {}
        if not info:
            self._cache["rider_model"] = None
            return None
        from piste.pipeline.characters import model_from_arrays

        name = sorted(info)[0]
        m = model_from_arrays(self.arrays, f"characters/{name}/", info[name])
        self._cache["rider_model"] = m
        return m

    def rider_lods(self):
        """The riders' LODs (:class:`piste.character.LOD` list, palettes as built) or None."""
        if "rider_lods" in self._cache:
            return self._cache["rider_lods"]
        info = self.manifest.get("characters") or {}
        if not info:
            return None
        from piste.pipeline.characters import lods_from_arrays

        name = sorted(info)[0]
        lods = lods_from_arrays(self.arrays, f"characters/{name}/", info[name], self.rider_model())
        self._cache["rider_lods"] = lods
        return lods


def load_bundle(path, verify: bool = True) -> Bundle:
    """Load a ``.piste`` bundle (see the module docstring).

    ``verify`` checks each member's SHA-256 against the manifest (the zip CRC is always checked).
    Raises :class:`~piste.errors.FormatError` on a missing file, a wrong format version, a missing
    or corrupt member.
    """
    from piste.lighting.lightmap import LightMap
    from piste.terrain.net import PatchNet

    path = Path(path)
    with _open(path) as zf:
        man = _manifest(path, zf)
        arrays = _read_arrays(path, zf, man["members"], verify)
    for need in ("terrain/control_points", "terrain/uv", "lightmap/atlas", "lightmap/rects"):
        if need not in arrays:
            raise FormatError(path, "required member is missing", field=f"{need}.npy")
    t = man.get("terrain", {})
    try:
        net = PatchNet(arrays["terrain/control_points"], uv=arrays["terrain/uv"], lightmap_rect=arrays["lightmap/rects"],
                       tol=t.get("tol"), name=t.get("name", "terrain"))
    except Exception as exc:
        raise FormatError(path, f"invalid terrain ({exc})", field="terrain/control_points.npy") from None
    lm_info = man.get("lightmap", {})
    lightmap = LightMap(atlas=arrays["lightmap/atlas"].astype(np.float32), rects=arrays["lightmap/rects"],
                        res=int(lm_info.get("res", 8)), gutter=int(lm_info.get("gutter", 1)), manifest=lm_info)
    try:
        lights = lights_from_dict(man.get("lights", {}))
        cameras = {c["name"]: camera_from_dict(c) for c in man.get("cameras", [])}
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(path, f"bad lights or cameras in the manifest ({exc})", field="manifest.json") from None
    vis = None
    if man.get("visibility"):
        from piste.pipeline.visibility import Visibility

        vis = Visibility.from_arrays({"patch_bits": arrays["visibility/patch_bits"],
                                      "object_bits": arrays["visibility/object_bits"]}, man["visibility"])
    line = arrays.get("terrain/centerline")
    return Bundle(path, man, arrays, net, lightmap, lights, cameras, vis, line)
