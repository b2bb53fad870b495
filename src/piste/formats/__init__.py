"""File formats.

gltf     load_gltf(path) -> piste.character.Model   (glTF 2.0: .gltf + .bin / data URIs, .glb)
bpt      read_bpt(path): Newell's Bézier patch text format (the teapot)
atomic   atomic file output (temp file + os.replace)
"""

from piste.formats.gltf import load_gltf

__all__ = ["load_gltf"]
