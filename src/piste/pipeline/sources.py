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
load_object_mesh(model) -> ObjectMesh        "builtin:<kind>" or a glTF file (meshes merged, Z up)
rider_matrices(net, riders) -> (n, 4, 4)     rider space (Y up, board along +X) -> world
object_matrices(net, objects, meshes) -> (m, 4, 4)   object space (Z up) -> world
heading_vector(degrees) -> (2,)              0 = +y, counter-clockwise seen from above
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from piste.errors import ConfigError, FormatError

__all__ = ["load_terrain", "load_heightfield", "load_rider_model", "load_object_mesh", "rider_matrices",
           "object_matrices", "heading_vector"]


def load_heightfield(spec) -> tuple[np.ndarray, tuple]:
    """``(z (H, W) float64 metres, (dx, dy))`` of a height-field terrain spec."""
    path = Path(spec.path)
    if spec.kind == "geotiff":
        from piste.formats.geotiff import read_geotiff

        dem = read_geotiff(path, fill=spec.nodata, vertical_units=spec.vertical_units)
        z, spacing = dem.z, spec.spacing or dem.spacing
    elif path.suffix.lower() == ".npz":
        try:
            data = np.load(path, allow_pickle=False)
        except Exception as exc:
            raise FormatError(path, f"not a readable .npz ({exc})") from None
        with data:
            names = list(data.files)
            key = spec.key or next((k for k in names if data[k].ndim == 2), None)
            if key is None or key not in names:
                raise FormatError(path, f"no 2-D height array{' ' + repr(spec.key) if spec.key else ''}; "
                                        f"arrays: {', '.join(names)}", field=spec.key or "")
            z = np.asarray(data[key], dtype=np.float64)
            spacing = spec.spacing
            if spacing is None:
                if "dx" in names:
                    dx = float(data["dx"])
                    spacing = (dx, float(data["dy"]) if "dy" in names else dx)
                elif "spacing" in names:
                    s = np.asarray(data["spacing"], dtype=np.float64).ravel()
                    spacing = (float(s[0]), float(s[-1]))
                else:
                    raise FormatError(path, "no spacing: give terrain.spacing in the scene or store 'dx'/'spacing'",
                                      field="spacing")
    else:
        from PIL import Image

        try:
            with Image.open(path) as im:
                z = np.asarray(im)
        except Exception as exc:
            raise FormatError(path, f"not a readable image ({exc})") from None
        if z.ndim == 3:
            z = z[..., 0]
        z = z.astype(np.float64)
        spacing = spec.spacing
    if z.ndim != 2 or min(z.shape) < spec.samples_per_patch + 1:
        raise FormatError(path, f"height field of shape {z.shape} is too small for {spec.samples_per_patch} "
                                "samples a patch")
    return z * spec.height_scale + spec.height_offset, tuple(float(s) for s in spacing)


def load_terrain(spec):
    """The :class:`piste.terrain.PatchNet` a :class:`~piste.world.scene_file.TerrainSpec` names."""
    from piste.terrain.net import PatchNet

    if spec.kind == "default":
        from piste.world.course import default_course

        return default_course(spec.seed)
    if spec.kind == "bpt":
        return PatchNet.from_bpt(spec.path)
    if spec.kind == "net":
        return PatchNet.load(spec.path)
    if spec.kind in ("heightfield", "geotiff"):
        from piste.terrain.fit import fit_heightfield

        z, spacing = load_heightfield(spec)
        return fit_heightfield(z, spacing, samples_per_patch=spec.samples_per_patch, smooth=spec.smooth,
                               name=Path(spec.path).name)
    raise ConfigError(f"unknown terrain kind {spec.kind!r}")


def load_rider_model(model: str, allow_paths=()):
    """A rider :class:`piste.character.Model`: ``builtin:rider`` or a skinned glTF file (whose URIs
    may also read ``allow_paths``, see :func:`piste.formats.gltf.load_gltf`)."""
    if model == "builtin:rider":
        from piste.character.rider import default_rider

        return default_rider(0)
    from piste.formats.gltf import load_gltf

    m = load_gltf(model, allow_paths=allow_paths)
    if m.skeleton is None or not m.clips:
        raise ConfigError(f"{model}: a rider model needs a skin and at least one animation")
    return m


def load_object_mesh(model: str, allow_paths=()):
    """An object mesh (object space Z up, base at the origin): a built-in kind or a glTF file's
    meshes merged (glTF Y up turned Z up, see :mod:`piste.pipeline.gltf_import`)."""
    from piste.world.objects import ObjectMesh, make_mesh

    if model.startswith("builtin:"):
        return make_mesh(model.split(":", 1)[1])
    from piste.formats.gltf import load_gltf
    from piste.pipeline.gltf_import import axis_matrix

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


def rider_matrices(net, riders) -> np.ndarray:
    """``(n, 4, 4)`` rider -> world matrices (the rider model is Y up, board along +X) standing on
    the exact surface, oriented to the slope, travelling along each rider's heading."""
    from piste.world.riders import surface_frame

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


def object_matrices(net, objects) -> np.ndarray:
    """``(m, 4, 4)`` object -> world matrices: upright, rotated by the heading, scaled, standing on
    the surface (z from :func:`piste.terrain.query.height_at` unless the position gives it)."""
    from piste.terrain.query import height_at

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
