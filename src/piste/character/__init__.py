"""Characters: glTF import, skeletons, clips, compression, skinning schemes, palettes, morphs.

Public API
----------
load_gltf(path) -> Model                      glTF 2.0 (.gltf + .bin / data URIs, .glb) import
Model, Skeleton, Pose, Track, Clip, SkinnedMesh, Light, Camera   data classes (model.py)
Skeleton.world_matrices(pose), Clip.sample(t, skeleton=None, loop=False, retarget=None)
compress_clip(clip, skeleton, max_error, virtual_distance) -> CompressedClip   (compress.py)
compression_report(model), clip_error(a, b, skeleton, virtual_distance)
blend_morphs(mesh, weights), morphs_to_null_bones(mesh, n_bones), morph_report  (morph.py)
"""

from piste.character.model import Camera, Clip, Light, Model, Pose, Skeleton, SkinnedMesh, Track
from piste.character.compress import CompressedClip, clip_error, compress_clip, compression_report
from piste.character.morph import NullBoneRig, blend_morphs, morph_report, morphs_to_null_bones, vertex_normals
from piste.formats.gltf import load_gltf

__all__ = [
    "Camera",
    "Clip",
    "CompressedClip",
    "NullBoneRig",
    "Light",
    "Model",
    "Pose",
    "Skeleton",
    "SkinnedMesh",
    "Track",
    "blend_morphs",
    "clip_error",
    "compress_clip",
    "compression_report",
    "load_gltf",
    "morph_report",
    "morphs_to_null_bones",
    "vertex_normals",
]
