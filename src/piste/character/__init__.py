"""Characters: skeletons, clips, compression, skinning schemes, palettes, morphs.

Public API
----------
Model, Skeleton, Pose, Track, Clip, SkinnedMesh, Light, Camera   data classes (model.py)
Skeleton.world_matrices(pose), Clip.sample(t, skeleton=None, loop=False, retarget=None)
compress_clip(clip, skeleton, max_error, virtual_distance) -> CompressedClip   (compress.py)
compression_report(model), clip_error(a, b, skeleton, virtual_distance)
blend_morphs(mesh, weights), morphs_to_null_bones(mesh, n_bones), morph_report  (morph.py)
skin(mesh, bone_matrices, scheme="exact"|"post_transform"|"blended", step, max_bones),
PostTransformMesh, BlendedMesh, skinning_report(model, steps)                   (skinning.py)
palette(mesh, step, max_bones) -> Palette, quantize_weights                     (palette.py)
make_batches, batch_mesh, check_batches, frame_bytes, Budget, BUDGETS           (batches.py)
stripify, unstripify, strip_stats                                               (strips.py)
make_lods, simplify_mesh, LOD                                                   (lod.py)
default_rider(seed=0) -> Model                                                  (rider.py)
retarget_clip(clip, skeleton, bone_map="builtin"|{src: dst}), builtin_bone_map, bone_roles (retarget.py)

glTF import is :func:`piste.formats.load_gltf` (the format layer builds these data classes; the
character layer does not import the formats).
"""

from piste.character.model import Camera, Clip, Light, Model, Pose, Skeleton, SkinnedMesh, Track
from piste.character.compress import CompressedClip, clip_error, compress_clip, compression_report
from piste.character.morph import NullBoneRig, blend_morphs, morph_report, morphs_to_null_bones, vertex_normals
from piste.character.skinning import BlendedMesh, PostTransformMesh, skin, skinning_report
from piste.character.palette import Palette, palette, quantize_weights
from piste.character.batches import BUDGETS, Batch, Budget, batch_mesh, check_batches, frame_bytes, make_batches
from piste.character.strips import strip_stats, stripify, unstripify
from piste.character.lod import LOD, make_lods, simplify_mesh
from piste.character.rider import default_rider
from piste.character.retarget import RetargetWarning, bone_roles, builtin_bone_map, retarget_clip

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
    "morph_report",
    "morphs_to_null_bones",
    "vertex_normals",
    "skin",
    "skinning_report",
    "PostTransformMesh",
    "BlendedMesh",
    "palette",
    "Palette",
    "quantize_weights",
    "make_batches",
    "batch_mesh",
    "check_batches",
    "frame_bytes",
    "Budget",
    "BUDGETS",
    "Batch",
    "stripify",
    "unstripify",
    "strip_stats",
    "make_lods",
    "simplify_mesh",
    "LOD",
    "default_rider",
    "RetargetWarning",
    "bone_roles",
    "builtin_bone_map",
    "retarget_clip",
]
