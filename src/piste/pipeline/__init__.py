"""The pipeline: from Blender (glTF) and a scene description to a ``.piste`` bundle to a fast preview.

The talk's "Pipelines": an off-the-shelf package for content creation, artists in control of lights,
cameras and animation, a fast in-game preview, and "pre-process everything you can".

Public API
----------
::

    build_scene(scene, out=None, cache_dir=None, progress=False, jobs=1) -> BuildResult   (build.py)
        validation, terrain, baked light map, character LODs/palettes/batches/strips, compressed objects
        with baked vertex colours, per-cell visibility; content-hash cache, byte-identical bundles
    Cache, content_key                      the step cache (cache.py)
    import_gltf, axis_matrix, write_scene_gltf
                                            glTF lights (KHR_lights_punctual) and cameras (gltf_import.py)
    Visibility, compute_visibility, culling_report
                                            per-cell patch/object bitsets (visibility.py)
    character_arrays                        the character step (characters.py)
    load_terrain, load_rider_model, load_object_mesh   reading a scene's sources (sources.py)
    load_bundle, Bundle, lights_from_dict, camera_from_dict   a built bundle as scene objects (bundle_objects.py)
    ScenePreview, render_image, render_frames, camera_at   the runtime: rendering a bundle (preview.py)
    build_default_scene                     the built-in default scene `piste demo` builds (default_scene.py)
    TiledSpec, build_tiles, TileError       large worlds: fit/bake/visibility a tile at a time (tiled_build.py)
    build_tiles_dask, dask_client, build_scene_tiles   the same tasks on a Dask cluster (dask_build.py)
    LiveScene, run_headless                 watch, rebuild, reload: ``piste view SCENE`` (live.py)

The scene file itself is :mod:`piste.world.scene_file` (``load_scene``); the bundle format is
:mod:`piste.formats.bundle` (``read_bundle``: arrays and metadata only).  Rendering imports OpenGL lazily: building needs none.
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562): `piste render BUNDLE` imports no build, bake,
# glTF, SSX or Dask module (tests/test_lazy_imports.py)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "tiled_build": ("TiledSpec", "TileError", "build_tiles", "spec_from_scene", "synthetic_spec"),
    "dask_build": ("build_scene_tiles", "build_tiles_dask", "dask_client"),
    "build": ("build_scene", "BuildResult", "BUILD_VERSION", "default_cache_dir"),
    "bundle_objects": ("load_bundle", "Bundle", "lights_from_dict", "camera_from_dict"),
    "default_scene": ("build_default_scene",),
    "cache": ("Cache", "content_key"),
    "characters": ("character_arrays",),
    "gltf_import": ("import_gltf", "axis_matrix", "write_scene_gltf"),
    "visibility": ("Visibility", "compute_visibility", "culling_report"),
    "sources": ("load_terrain", "load_rider_model", "load_object_mesh"),
    "preview": ("ScenePreview", "render_image", "render_frames", "camera_at"),
    "live": ("LiveScene", "run_headless"),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.pipeline.bundle_objects import Bundle, camera_from_dict, lights_from_dict, load_bundle  # noqa: F401
    from piste.pipeline.build import BUILD_VERSION, BuildResult, build_scene, default_cache_dir  # noqa: F401
    from piste.pipeline.cache import Cache, content_key  # noqa: F401
    from piste.pipeline.default_scene import build_default_scene  # noqa: F401
    from piste.pipeline.characters import character_arrays  # noqa: F401
    from piste.pipeline.gltf_import import axis_matrix, import_gltf, write_scene_gltf  # noqa: F401
    from piste.pipeline.live import LiveScene, run_headless  # noqa: F401
    from piste.pipeline.preview import ScenePreview, camera_at, render_frames, render_image  # noqa: F401
    from piste.pipeline.sources import load_object_mesh, load_rider_model, load_terrain  # noqa: F401
    from piste.pipeline.visibility import Visibility, compute_visibility, culling_report  # noqa: F401
    from piste.pipeline.tiled_build import TiledSpec, TileError, build_tiles, spec_from_scene, synthetic_spec  # noqa: F401
    from piste.pipeline.dask_build import build_scene_tiles, build_tiles_dask, dask_client  # noqa: F401
