"""File formats.

gltf     load_gltf(path) -> piste.character.Model   (glTF 2.0: .gltf + .bin / data URIs, .glb)
bpt      read_bpt(path): Newell's Bézier patch text format (the teapot)
atomic   atomic file output (temp file + os.replace)
geotiff  read_geotiff(path) -> DemRaster (heights + georeferencing), write_geotiff (tifffile: the dask extra)
bundle   read_bundle(path) -> BundleData (manifest + arrays), write_bundle: the .piste bundle `piste build`
         writes (the scene objects of a bundle: piste.pipeline.load_bundle)
"""

from piste.formats.gltf import load_gltf
from piste.formats.bundle import BundleData, load_bundle, read_bundle, read_manifest, write_bundle
from piste.formats.geotiff import DemRaster, read_geotiff, write_geotiff

__all__ = ["load_gltf", "read_bundle", "read_manifest", "write_bundle", "BundleData", "load_bundle", "DemRaster",
           "read_geotiff", "write_geotiff"]
