"""Faces that move: morph targets (or their null-bone fit) added after blended-matrix skinning;
the default rider blinks and talks, glTF expressions take their turns; rendered face pixels differ
between two times of the face animation while the rest of the frame stays put."""

from __future__ import annotations

import numpy as np
import pytest


def test_face_weights_blink_and_mouth():
    from piste.character.morph import face_weights

    names = ["smile", "blink", "shout"]
    closed = face_weights(names, 0.075, [0])[0]
    opened = face_weights(names, 1.0, [0])[0]
    assert closed[1] == pytest.approx(1.0) and opened[1] == 0.0
    w = face_weights(names, 0.0, [0])
    mouth = np.array([face_weights(names, t, [0])[0] for t in np.linspace(0.0, 10.0, 101)])
    assert mouth[:, 0].max() > 0.9 and mouth[:, 2].max() > 0.9
    assert (np.minimum(mouth[:, 0], mouth[:, 2]) == 0).all()  # never both at once
    # riders keep their own rhythm
    assert not np.allclose(face_weights(names, 0.075, [0, 1])[0], face_weights(names, 0.075, [0, 1])[1])
    # other targets (glTF expressions) take turns, one at a time
    ex = np.array([face_weights(["Angry", "Surprised", "Sad"], t, [0])[0] for t in np.linspace(0, 6, 61)])
    assert (ex.max(axis=0) > 0.9).all() and ((ex > 0).sum(axis=1) <= 1).all()
    assert w.shape == (1, 3)


@pytest.mark.parametrize("mode", ["morph", "null_bones"])
def test_face_skin_equals_skinning_the_morphed_mesh(mode):
    """skin(p + d) == skin(p) + R d: FaceSkin on top of BlendedMesh equals BlendedMesh built on
    the morphed bind positions (exactly for morph targets; null bones to their fit)."""
    from piste.character import BlendedMesh, default_rider, make_lods
    from piste.character.morph import FaceSkin, blend_morphs

    lod = make_lods(default_rider(0).meshes[0])[1]
    mesh = lod.mesh
    rng = np.random.default_rng(1)
    sk = default_rider(0).skeleton
    b = sk.n_bones
    skin = np.tile(np.eye(4), (2, b, 1, 1))
    angles = rng.normal(0, 0.3, (2, b))
    skin[:, :, 0, 0] = skin[:, :, 1, 1] = np.cos(angles)
    skin[:, :, 0, 1], skin[:, :, 1, 0] = -np.sin(angles), np.sin(angles)
    skin[:, :, :3, 3] = rng.normal(0, 0.1, (2, b, 3))
    w = np.array([[0.3, 1.0, 0.0], [0.0, 0.5, 0.8]], np.float32)
    base = BlendedMesh(lod.palette, mesh.positions, mesh.normals)
    pos, nrm = base.apply_many(skin)
    fs = FaceSkin(mesh, lod.palette.index, mode)
    assert fs and len(fs.vertices) < mesh.n_vertices // 4  # only the face is touched
    fs.apply(pos, nrm, base.palette_matrices(skin), w)
    for i in range(2):
        mp, mn = blend_morphs(mesh, w[i])
        if mode == "null_bones":
            mp = fs.rig.apply(mesh, w[i])
            mn = mesh.normals
        ref_p, ref_n = BlendedMesh(lod.palette, mp, mn).apply_many(skin[i:i + 1])
        assert np.abs(pos[i] - ref_p[0]).max() < 1e-4
        if mode == "morph":
            # normals: the skinned base normal is unit before the morph's delta is added (a blended
            # matrix is not a rotation): the same direction within ~1.5 degrees
            assert np.abs(nrm[i] - ref_n[0]).max() < 0.03


def _face_camera(scene, t):
    from piste.world.camera import Camera

    m = scene.riders.state(t).matrix[0]
    head = m[:3, 3] + m[:3, 1] * 1.55
    return Camera(head + m[:3, 2] * 0.9 + m[:3, 1] * 0.05, head, fov_y=40.0, near=0.05, far=500.0)


@pytest.fixture(scope="module")
def rider_scene():
    from piste.world.scene import Scene

    return Scene.default(0, objects=False)


@pytest.mark.parametrize("mode", ["morph", "null_bones"])
def test_rendered_face_moves(gl, rider_scene, mode):
    from piste.render.scene_renderer import SceneRenderer

    cam = _face_camera(rider_scene, 1.0)
    r = SceneRenderer(rider_scene, size=(160, 112), ctx=gl, lightmap=None, shadows=False, face=mode)
    r.terrain.resident_wait = True  # every frame on the same (resident) path
    try:
        opened = r.render(1.0, camera=cam, face_time=1.0).image[..., :3].astype(int)
        closed = r.render(1.0, camera=cam, face_time=0.075).image[..., :3].astype(int)  # mid-blink
    finally:
        r.release()
    d = np.abs(opened - closed).max(-1) > 20
    assert d.sum() >= 10  # the eyelids
    ys, xs = np.nonzero(d)
    assert np.ptp(ys) < 40 and np.ptp(xs) < 40  # ... and nothing else: one small region of the face


def test_gltf_expressions_play(gl, gltf_model, rider_scene):
    """RobotExpressive's expressions (morph targets on its head meshes) play on a rider cast."""
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.riders import pack_for, rider_model
    from piste.world.scene import Scene
    from piste.world.camera import Camera

    m = rider_model(gltf_model("RobotExpressive"))
    assert m.meshes[0].morph_names == ["Angry", "Surprised", "Sad"]
    s = rider_scene
    cast = Scene(s.net, s.line, s.lights, model=m, pack=pack_for(m, 1, ahead=3.0, across=0.0), start=150.0)
    st = cast.riders.state(1.0)
    mt = st.matrix[0]
    top = mt[:3, 3] + mt[:3, 1] * (cast.lods[0].mesh.bounds()[1][1] * 0.85)
    cam = Camera(top + mt[:3, 2] * 2.0, top, fov_y=40.0, near=0.05, far=500.0)
    r = SceneRenderer(s, size=(160, 112), ctx=gl, lightmap=None, shadows=False, casts=[cast])
    r.terrain.resident_wait = True
    try:
        imgs = [r.render(1.0, camera=cam, face_time=ft).image[..., :3].astype(int) for ft in (0.0, 1.0, 3.0)]
    finally:
        r.release()
    # t=0: no expression; t=1: the first at full weight; t=3: the second
    assert (np.abs(imgs[0] - imgs[1]).max(-1) > 20).sum() >= 10
    assert (np.abs(imgs[1] - imgs[2]).max(-1) > 20).sum() >= 10
