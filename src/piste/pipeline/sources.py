"""Reading a scene's sources: the terrain net, rider and object models, placements.

Height-field images: row ``r``, column ``c`` of the image is the height at ``x = c * dx``,
``y = r * dy`` (the image's top row at ``y = 0``); 16-bit PNGs keep their 65,536 levels.
Heights are ``value * height_scale + height_offset`` metres.  A GeoTIFF (kind ``geotiff``) brings
its own spacing, nodata and vertical units (:func:`piste.formats.geotiff.read_geotiff`); its
sample ``[0, 0]`` (the south-west corner) is placed at x = y = 0 (float32 rendering keeps
centimetres only near the origin), ``spacing`` in the scene overrides the file's.

API
---
load_terrain(spec) -> PatchNet               a TerrainSpec's net
load_rider_model(model) -> Model             "builtin:rider" or a glTF file
add_rider_clips(model, [(file, bone_map)])   clips from glTF files retargeted, or an .afl bank's (clips_from)
load_object_mesh(model) -> ObjectMesh        "builtin:<kind>" or a glTF file (meshes merged, Z up)
rider_matrices(net, riders) -> (n, 4, 4)     rider space (Y up, board along +X) -> world
object_matrices(net, objects, meshes) -> (m, 4, 4)   object space (Z up) -> world
heading_vector(degrees) -> (2,)              0 = +y, counter-clockwise seen from above
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.character.retarget import add_clips
from piste.character.rider import default_rider
from piste.errors import ConfigError, FormatError, PisteError
from piste.formats.geotiff import read_geotiff
from piste.formats.gltf import load_gltf
from piste.formats.limits import MAX_HEIGHTFIELD_SAMPLES
from piste.formats.safe_io import open_file
from piste.pipeline.gltf_import import axis_matrix
from piste.pipeline.ssx_level import load_level
from piste.formats.ssx.afl import read_afl
from piste.pipeline.ssx_rider import afl_rider_clips, load_mpf_rider
from piste.terrain.fit import fit_heightfield
from piste.terrain.net import PatchNet
from piste.terrain.query import height_at
from piste.world.course import default_course
from piste.world.objects import ObjectMesh, make_mesh
from piste.world.riders import surface_frame

if TYPE_CHECKING:
    from piste.character.model import Model
    from piste.world.scene_file import ActorSpec, TerrainSpec

#: paths a glTF file's URIs may also read (:func:`piste.formats.gltf.load_gltf`)
AllowPaths = Iterable[str | os.PathLike[str]]

#: largest height-field file (PNG, .npz) read
MAX_HEIGHTFIELD_FILE_BYTES = 1 << 30

__all__ = ["load_terrain", "load_heightfield", "load_rider_model", "load_object_mesh", "rider_matrices",
           "object_matrices", "heading_vector"]


def load_heightfield(spec: TerrainSpec) -> tuple[np.ndarray, tuple[float, ...]]:
    """``(z (H, W) float64 metres, (dx, dy))`` of a height-field terrain spec."""
    path = Path(spec.path)
    if spec.kind == "geotiff":
        dem = read_geotiff(path, fill=spec.nodata, vertical_units=spec.vertical_units)
        z, spacing = dem.z, spec.spacing or dem.spacing
    elif path.suffix.lower() == ".npz":
        z, spacing = _npz_heightfield(path, spec)
    else:
        from PIL import Image

        try:  # regular files only, opened race-free without links (piste.formats.safe_io)
            with open_file(path, MAX_HEIGHTFIELD_FILE_BYTES, what="height field") as fh, Image.open(fh) as im:
                w, h = im.size  # from the header: checked before a pixel is decoded
                if w * h > MAX_HEIGHTFIELD_SAMPLES:
                    raise FormatError(path, f"height field of {w} x {h} samples is more than the limit of "
                                            f"{MAX_HEIGHTFIELD_SAMPLES} (4096 x 4096)")
                z = np.asarray(im)
        except PisteError:
            raise
        except Exception as exc:
            raise FormatError(path, f"not a readable image ({exc})") from None
        if z.ndim == 3:
            z = z[..., 0]
        z = z.astype(np.float64)
        spacing = spec.spacing
    if not np.all(np.isfinite(z)):
        raise FormatError(path, f"height field has {int(np.count_nonzero(~np.isfinite(z)))} non-finite samples")
    if z.ndim != 2 or min(z.shape) < spec.samples_per_patch + 1:
        raise FormatError(path, f"height field of shape {z.shape} is too small for {spec.samples_per_patch} "
                                "samples a patch")
    return z * spec.height_scale + spec.height_offset, tuple(float(s) for s in spacing)


def _member_shape(path: str | Path, data: Any, name: str) -> tuple[int, ...]:
    """Shape of ``.npz`` member ``name`` from its ``.npy`` header alone (nothing decompressed)."""
    try:
        with data.zip.open(name + ".npy") as fh:
            version = np.lib.format.read_magic(fh)
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, _, dtype = read(fh)
    except Exception as exc:
        raise FormatError(path, f"array {name!r} has an unreadable header ({type(exc).__name__}: {exc})",
                          field=name) from None
    if dtype.kind not in "biuf":
        raise FormatError(path, f"array {name!r} holds {dtype}, expected numbers", field=name)
    return tuple(shape)


def _npz_array(path: str | Path, data: Any, name: str, max_size: int) -> np.ndarray:
    shape = _member_shape(path, data, name)
    if int(np.prod(shape, dtype=np.float64)) > max_size:
        raise FormatError(path, f"array {name!r} of shape {shape} is more than the limit of {max_size} values",
                          field=name)
    try:
        return np.asarray(data[name], dtype=np.float64)
    except Exception as exc:
        raise FormatError(path, f"array {name!r} is unreadable ({type(exc).__name__}: {exc})", field=name) from None


def _spacing_value(path: str | Path, name: str, a: np.ndarray, index: int) -> float:
    flat = a.ravel()
    if flat.size == 0 or not np.isfinite(flat[index]) or not flat[index] > 0:
        raise FormatError(path, f"expected a spacing > 0 metres, got {a.tolist()!r}", field=name)
    return float(flat[index])


def _npz_heightfield(path: str | Path, spec: TerrainSpec) -> tuple[np.ndarray, tuple[float, float]]:
    """``(z, spacing)`` from an ``.npz``: every member's shape and type checked from its header
    before it is read, the height array capped at MAX_HEIGHTFIELD_SAMPLES."""
    fh = open_file(path, MAX_HEIGHTFIELD_FILE_BYTES, what="height field")  # race-free, no links
    try:
        data = np.load(fh, allow_pickle=False)
    except Exception as exc:
        fh.close()
        raise FormatError(path, f"not a readable .npz ({type(exc).__name__}: {exc})") from None
    if not hasattr(data, "files"):
        fh.close()
        raise FormatError(path, "not an .npz archive (a single .npy array)")
    with fh, data:
        names = list(data.files)
        if spec.key is not None:
            key = spec.key
        else:
            key = next((k for k in names if len(_member_shape(path, data, k)) == 2), None)
        if key is None or key not in names:
            raise FormatError(path, f"no 2-D height array{' ' + repr(spec.key) if spec.key else ''}; "
                                    f"arrays: {', '.join(names)}", field=spec.key or "")
        z = _npz_array(path, data, key, MAX_HEIGHTFIELD_SAMPLES)
        spacing = spec.spacing
        if spacing is None:
            if "dx" in names:
                dx = _spacing_value(path, "dx", _npz_array(path, data, "dx", 16), 0)
                dy = _spacing_value(path, "dy", _npz_array(path, data, "dy", 16), 0) if "dy" in names else dx
                spacing = (dx, dy)
            elif "spacing" in names:
                sp = _npz_array(path, data, "spacing", 16)
                spacing = (_spacing_value(path, "spacing", sp, 0), _spacing_value(path, "spacing", sp, -1))
            else:
                raise FormatError(path, "no spacing: give terrain.spacing in the scene or store 'dx'/'spacing'",
                                  field="spacing")
    return z, spacing


def load_terrain(spec: TerrainSpec) -> PatchNet:
    """The :class:`piste.terrain.PatchNet` a :class:`~piste.world.scene_file.TerrainSpec` names."""
    if spec.kind == "default":
        return default_course(spec.seed)
    if spec.kind == "ssx_pbd":  # UVs into the level's texture atlas (piste.pipeline.ssx_level)
        return load_level(spec.path).net
    if spec.kind == "bpt":
        return PatchNet.from_bpt(spec.path)
    if spec.kind == "net":
        return PatchNet.load(spec.path)
    if spec.kind in ("heightfield", "geotiff"):
        z, spacing = load_heightfield(spec)
        return fit_heightfield(z, spacing, samples_per_patch=spec.samples_per_patch, smooth=spec.smooth,
                               name=Path(spec.path).name)
    raise ConfigError(f"unknown terrain kind {spec.kind!r}")


def load_rider_model(model: str, allow_paths: AllowPaths = ()) -> Model:
    """A rider :class:`piste.character.Model`: ``builtin:rider`` or a skinned glTF file (whose URIs
    may also read ``allow_paths``, see :func:`piste.formats.gltf.load_gltf`)."""
    if model == "builtin:rider":
        return default_rider(0)
    if model.lower().endswith(".mpf"):  # scene key model = "ssx:RIDER.mpf"
        return load_mpf_rider(model)
    m = load_gltf(model, allow_paths=allow_paths)
    if m.skeleton is None or not m.clips:
        raise ConfigError(f"{model}: a rider model needs a skin and at least one animation")
    return m


def add_rider_clips(model: Model, sources: Iterable[tuple[str | os.PathLike[str], str | dict[str, str] | None]],
                    allow_paths: AllowPaths = ()) -> Model:
    """``model`` with the clips of each ``(file, bone_map)`` in ``sources`` retargeted onto it
    (:func:`piste.character.retarget.add_clips`, relative rule baked; a scene's ``clips_from``).
    An ``.afl`` file (SSX Tricky animation bank, ``bone_map`` None) adds its clips to an ``.mpf``
    rider (:func:`_add_afl_clips`)."""
    for file, bone_map in sources:
        if str(file).lower().endswith(".afl"):
            model = _add_afl_clips(model, file)
            continue
        src = load_gltf(file, allow_paths=allow_paths)
        if src.skeleton is None or not src.clips:
            raise ConfigError(f"{file}: clips_from needs a file with a skin and at least one animation")
        model = add_clips(model, src, bone_map if bone_map is not None else "builtin")
    return model


def _add_afl_clips(model: Model, file: str | os.PathLike[str]) -> Model:
    """A copy of ``model`` (an ``.mpf`` rider, :func:`piste.pipeline.ssx_rider.load_mpf_rider`) with
    the clips of the ``.afl`` bank ``file`` (:func:`piste.pipeline.ssx_rider.afl_rider_clips`, root
    tracks lifted as the rider is); a name the model already has gets the file's stem in front
    (``"bank:clip_1234abcd"``)."""
    if not getattr(model, "files", None) or model.skeleton is None:
        raise ConfigError(f"{file}: an .afl bank plays only on an ssx:<RIDER.mpf> model")
    afl = read_afl(file)
    clips = afl_rider_clips(model, afl)
    if not clips:
        raise ConfigError(f"{file}: clips_from needs an .afl with at least one clip with a body track "
                          f"({len(afl.clips)} clips, none with one)")
    new = dict(model.clips)
    for n, c in clips.items():
        key = n if n not in new else f"{Path(file).stem}:{n}"
        c.name = key
        new[key] = c
    return replace(model, clips=new)


def load_object_mesh(model: str, allow_paths: AllowPaths = ()) -> ObjectMesh:
    """An object mesh (object space Z up, base at the origin): a built-in kind or a glTF file's
    meshes merged (glTF Y up turned Z up, see :mod:`piste.pipeline.gltf_import`)."""
    if model.startswith("builtin:"):
        return make_mesh(model.split(":", 1)[1])
    m = load_gltf(model, allow_paths=allow_paths)
    if not m.meshes:
        raise ConfigError(f"{model}: no meshes to use as an object")
    a = axis_matrix("y")
    off = np.cumsum([0] + [x.n_vertices for x in m.meshes])[:-1]
    pos = np.concatenate([x.positions for x in m.meshes]).astype(np.float64) @ a.T
    nrm = np.concatenate([x.normals for x in m.meshes]).astype(np.float64) @ a.T
    uv = np.concatenate([x.uv for x in m.meshes])
    idx = np.concatenate([x.indices + o for x, o in zip(m.meshes, off)])
    return ObjectMesh(Path(model).stem, pos, nrm, uv, idx)


def heading_vector(degrees: float) -> np.ndarray:
    """Unit xy travel direction for a heading in degrees: 0 = +y, 90 = -x (counter-clockwise)."""
    h = np.radians(float(degrees))
    return np.array([-np.sin(h), np.cos(h)])


def rider_matrices(net: PatchNet, riders: Sequence[ActorSpec]) -> np.ndarray:
    """``(n, 4, 4)`` rider -> world matrices (the rider model is Y up, board along +X) standing on
    the exact surface, oriented to the slope, travelling along each rider's heading."""
    if not riders:
        return np.zeros((0, 4, 4))
    xy = np.array([r.position[:2] for r in riders], dtype=np.float64)
    heading = np.stack([heading_vector(r.heading) for r in riders])
    try:
        anchor, normal, fwd = surface_frame(net, xy, heading)
    except Exception as exc:
        raise ConfigError(f"riders: {exc}") from None
    for i, r in enumerate(riders):
        if len(r.position) == 3:
            anchor[i, 2] = r.position[2]
    scale = np.array([r.scale for r in riders])[:, None]
    m = np.zeros((len(riders), 4, 4))
    m[:, :3, 0] = fwd * scale
    m[:, :3, 1] = normal * scale
    m[:, :3, 2] = np.cross(fwd, normal) * scale
    m[:, :3, 3] = anchor
    m[:, 3, 3] = 1.0
    return m


def object_matrices(net: PatchNet, objects: Sequence[ActorSpec]) -> np.ndarray:
    """``(m, 4, 4)`` object -> world matrices: upright, rotated by the heading, scaled, standing on
    the surface (z from :func:`piste.terrain.query.height_at` unless the position gives it)."""
    if not objects:
        return np.zeros((0, 4, 4))
    xy = np.array([o.position[:2] for o in objects], dtype=np.float64)
    z, hit, _, _ = height_at(net, xy)
    m = np.zeros((len(objects), 4, 4))
    for i, o in enumerate(objects):
        if len(o.position) == 3:
            zi = o.position[2]
        elif hit[i]:
            zi = z[i]
        else:
            raise ConfigError(f"objects: {o.name!r} at {list(o.position)} lies off the terrain: give [x, y, z]")
        h = np.radians(o.heading)
        c, s = np.cos(h), np.sin(h)
        m[i, :3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) * o.scale
        m[i, :3, 3] = (xy[i, 0], xy[i, 1], zi)
        m[i, 3, 3] = 1.0
    return m
