"""Characters: glTF import, skeletons, clips, compression, skinning schemes, palettes, morphs.

Public API
----------
load_gltf(path) -> Model                      glTF 2.0 (.gltf + .bin / data URIs, .glb) import
Model, Skeleton, Pose, Track, Clip, SkinnedMesh, Light, Camera   data classes (model.py)
Skeleton.world_matrices(pose), Clip.sample(t, skeleton=None, loop=False, retarget=None)
compress_clip(clip, skeleton, max_error, virtual_distance) -> CompressedClip   (compress.py)
blend_morphs(mesh, weights), morphs_to_null_bones(mesh, n_bones)                (morph.py)
"""

from piste.character.model import Camera, Clip, Light, Model, Pose, Skeleton, SkinnedMesh, Track
from piste.character.morph import blend_morphs, vertex_normals
from piste.formats.gltf import load_gltf

__all__ = [
    "Camera",
    "Clip",
    "Light",
    "Model",
    "Pose",
    "Skeleton",
    "SkinnedMesh",
    "Track",
    "blend_morphs",
    "load_gltf",
    "vertex_normals",
]
