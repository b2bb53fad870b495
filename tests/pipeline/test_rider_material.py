"""A glTF rider keeps its material's alpha mode and double-sidedness: the character step bakes
the MASK cutoff into the texture's alpha and stores the material in the bundle, and the runtime's
character pass gets it (alpha test, back-face culling)."""

from __future__ import annotations

import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from piste.character.model import Model, SkinnedMesh
from piste.formats.gltf_ext import MaterialInfo
from piste.pipeline.characters import merged_mesh, rider_material


def _prim(name, material, alpha=(10, 100, 150, 250)):
    tex = np.zeros((2, 2, 4), np.uint8)
    tex[..., :3] = 200
    tex[..., 3] = np.reshape(alpha, (2, 2))
    return SkinnedMesh(name, np.eye(3), np.array([[0, 1, 2]]), uv=np.zeros((3, 2)), texture=tex, material=material)


def test_rider_material_from_its_primitives():
    assert rider_material([_prim("a", None)]) is None
    m = rider_material([_prim("a", MaterialInfo()), _prim("b", MaterialInfo(alpha_mode="BLEND", double_sided=True))])
    assert m.alpha_mode == "MASK" and m.double_sided
    m = rider_material([_prim("a", MaterialInfo()), _prim("b", MaterialInfo())])
    assert m.alpha_mode == "OPAQUE" and not m.double_sided


def test_single_primitive_mask_cutoff_baked_into_the_texture():
    model = Model("m", None, [_prim("a", MaterialInfo(alpha_mode="MASK", alpha_cutoff=0.3))])
    mesh = merged_mesh(model)
    assert mesh.material.alpha_mode == "MASK"
    assert mesh.texture[..., 3].tolist() == [[0, 255], [255, 255]]  # cutoff 0.3 = 77
    assert (mesh.texture[..., :3] == 200).all()
    opaque = merged_mesh(Model("m", None, [_prim("a", MaterialInfo())]))
    assert opaque.material.alpha_mode == "OPAQUE" and opaque.texture[..., 3].tolist() == [[10, 100], [150, 250]]


def test_scene_file_gltf_rider_material_reaches_the_character_pass(small_scene, gl, gltf_model, piste_cache):
    from piste.formats.gltf import load_gltf
    from piste.pipeline import build_scene, load_bundle
    from piste.pipeline.characters import character_arrays, model_from_arrays
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.world.scene_file import load_scene

    gltf_model("CesiumMan")  # skips without the test data
    data = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
    src = data / "gltf" / "CesiumMan" / "CesiumMan.glb"
    # the bundle's arrays round trip a MASK, double-sided material
    cesium = load_gltf(src)
    masked = replace(cesium, meshes=[replace(m, material=MaterialInfo(alpha_mode="MASK", double_sided=True))
                                     for m in cesium.meshes])
    arrays, meta = character_arrays(masked, ratios=(1.0,))
    back = model_from_arrays(arrays, "", meta).meshes[0].material
    assert (back.alpha_mode, back.double_sided) == ("MASK", True)
    # a scene file's glTF rider: its own (single-sided, opaque) material drives the pass
    scene = small_scene(riders=True)
    shutil.copy(src, scene.parent / "CesiumMan.glb")
    text = scene.read_text().replace('[[objects]]\nname = "tree"', '[[riders]]\nname = "cesium"\nmodel = "CesiumMan.glb"\n'
                                     'position = [66.0, 58.0]\n\n[[objects]]\nname = "tree"', 1)
    scene.write_text(text)
    out = scene.with_suffix(".piste")
    build_scene(load_scene(scene), out=out)
    b = load_bundle(out)
    want = rider_material(cesium.meshes)
    p = ScenePreview(b, size=(64, 48), ctx=gl)
    try:
        p.render(camera_at(b), 0.3)
        passes = p.renderer.cast_passes
        assert [(cp.alpha_test, cp.cull_back) for cp in passes] == [(False, False),
                                                                   (want.alpha_mode == "MASK", not want.double_sided)]
    finally:
        p.release()
