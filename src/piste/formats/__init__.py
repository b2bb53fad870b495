"""File formats.

Modules::

    gltf     load_gltf(path) -> piste.character.Model   (glTF 2.0: .gltf + .bin / data URIs, .glb)
    bpt      read_bpt(path): Newell's Bézier patch text format (the teapot)
    atomic   atomic file output (temp file + os.replace)
    geotiff  read_geotiff(path) -> DemRaster (heights + georeferencing), write_geotiff (tifffile: the dask extra)
    bundle   read_bundle(path) -> BundleData (manifest + arrays), write_bundle: the .piste bundle `piste build`
             writes (the scene objects of a bundle: piste.pipeline.load_bundle)
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "gltf": ("load_gltf",),
    "bundle": ("read_bundle", "read_manifest", "write_bundle", "BundleData", "load_bundle"),
    "geotiff": ("DemRaster", "read_geotiff", "write_geotiff"),
    "bpt": ("read_bpt",),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.formats.gltf import load_gltf  # noqa: F401
    from piste.formats.bundle import BundleData, load_bundle, read_bundle, read_manifest, write_bundle  # noqa: F401
    from piste.formats.geotiff import DemRaster, read_geotiff, write_geotiff  # noqa: F401
    from piste.formats.bpt import read_bpt  # noqa: F401
