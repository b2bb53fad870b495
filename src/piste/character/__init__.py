"""Characters: skeletons, clips, compression, skinning schemes, palettes, morphs.

Public API
----------
::

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

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py); ``palette`` is also
# a submodule's name and stays the function (piste._LazyPackage)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "model": ("Clip", "Model", "Pose", "Skeleton", "SkinnedMesh", "Track"),
    "compress": ("CompressedClip", "clip_error", "compress_clip", "compression_report"),
    "morph": ("NullBoneRig", "blend_morphs", "morph_report", "morphs_to_null_bones", "vertex_normals"),
    "skinning": ("skin", "skinning_report", "PostTransformMesh", "BlendedMesh"),
    "palette": ("palette", "Palette", "quantize_weights"),
    "batches": ("make_batches", "batch_mesh", "check_batches", "frame_bytes", "Budget", "BUDGETS", "Batch"),
    "strips": ("stripify", "unstripify", "strip_stats"),
    "lod": ("make_lods", "simplify_mesh", "LOD"),
    "rider": ("default_rider",),
    "retarget": ("RetargetWarning", "bone_roles", "builtin_bone_map", "retarget_clip"),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.character.model import Clip, Model, Pose, Skeleton, SkinnedMesh, Track  # noqa: F401
    from piste.character.compress import CompressedClip, clip_error, compress_clip, compression_report  # noqa: F401
    from piste.character.morph import NullBoneRig, blend_morphs, morph_report, morphs_to_null_bones, vertex_normals  # noqa: F401
    from piste.character.skinning import BlendedMesh, PostTransformMesh, skin, skinning_report  # noqa: F401
    from piste.character.palette import Palette, palette, quantize_weights  # noqa: F401
    from piste.character.batches import BUDGETS, Batch, Budget, batch_mesh, check_batches, frame_bytes, make_batches  # noqa: F401
    from piste.character.strips import strip_stats, stripify, unstripify  # noqa: F401
    from piste.character.lod import LOD, make_lods, simplify_mesh  # noqa: F401
    from piste.character.rider import default_rider  # noqa: F401
    from piste.character.retarget import RetargetWarning, bone_roles, builtin_bone_map, retarget_clip  # noqa: F401
