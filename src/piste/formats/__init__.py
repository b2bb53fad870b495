"""File formats.

gltf     load_gltf(path) -> piste.character.Model   (glTF 2.0: .gltf + .bin / data URIs, .glb)
bpt      read_bpt(path): Newell's Bézier patch text format (the teapot)
atomic   atomic file output (temp file + os.replace)
bundle   load_bundle(path) -> Bundle, write_bundle: the .piste bundle `piste build` writes
"""

from piste.formats.gltf import load_gltf
from piste.formats.bundle import Bundle, load_bundle, write_bundle

__all__ = ["load_gltf", "load_bundle", "write_bundle", "Bundle"]
