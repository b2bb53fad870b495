"""Scene passes: riders and objects lit per vertex (shader vs numpy), non-uniform object scale,
specular pass, reference images."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from piste.lighting import AmbientLight, DirectionalLight, Lights
from piste.lighting.vertex import choose_lights, choose_lights_many, vertex_light

LIGHTS = Lights((
    AmbientLight((0.35, 0.4, 0.5), 0.5),
    DirectionalLight((-0.35, 0.75, -0.55), (1.0, 0.9, 0.75), 0.8, name="key"),
    DirectionalLight((-0.9, 0.2, -0.2), (0.3, 0.5, 1.0), 0.5, name="fill"),
    DirectionalLight((0.1, 0.95, 0.1), (1.0, 0.3, 0.2), 0.4, name="rim"),
))


def _ortho_camera(center, size, aspect=1.0):
    from piste.world.camera import Camera

    c = np.asarray(center, float)
    return Camera(eye=c + (0, 0, 50.0), target=c, up=(0, 1.0, 0), ortho_height=size, aspect=aspect, near=1.0, far=100.0)


def _pixel(vp, p, w, h):
    q = vp @ np.append(p, 1.0)
    x = (q[0] / q[3] * 0.5 + 0.5) * w
    y = (1.0 - (q[1] / q[3] * 0.5 + 0.5)) * h  # image rows top first
    return int(x), int(y)


def _quads_mesh(normals, spacing=1.0):
    """One quad per normal, laid out in a row in the z = 0 plane, all four corners carrying it."""
    from piste.character import SkinnedMesh

    k = len(normals)
    pos, nrm, tri = [], [], []
    for i, n in enumerate(normals):
        x = i * spacing
        pos += [(x, 0, 0), (x + 0.8 * spacing, 0, 0), (x + 0.8 * spacing, 0.8 * spacing, 0), (x, 0.8 * spacing, 0)]
        nrm += [n] * 4
        tri += [(4 * i, 4 * i + 1, 4 * i + 2), (4 * i, 4 * i + 2, 4 * i + 3)]
    return SkinnedMesh("quads", np.array(pos), tri, normals=np.array(nrm), uv=np.full((4 * k, 2), 0.5))


def test_character_shader_lighting_matches_numpy(gl):
    from piste.render.character_pass import CharacterPass
    from piste.render.context import Offscreen

    rng = np.random.default_rng(3)
    normals = rng.normal(size=(12, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    mesh = _quads_mesh(normals)
    lod = SimpleNamespace(mesh=mesh)
    tex = np.full((4, 4, 4), 255, np.uint8)
    cp = CharacterPass(gl, [lod], tex, max_riders=1)
    target = Offscreen(gl, (192, 32))
    try:
        cam = _ortho_camera((6.0, 0.4, 0.0), 2.0, aspect=6.0)
        vp = cam.view_projection()
        vl = choose_lights_many(LIGHTS, np.zeros((1, 3)))
        cp.upload([(np.array([0]), mesh.positions[None], mesh.normals[None])])
        target.use()
        target.clear((0, 0, 0, 1))
        cp.draw(vp, cam.eye, vl, light_only=True)
        img = target.read()
    finally:
        cp.release()
        target.release()
    want = np.clip(vertex_light(normals, vl[0]), 0, 1) * 255
    for i in range(len(normals)):
        x, y = _pixel(vp, (i + 0.4, 0.4, 0.0), 192, 32)
        np.testing.assert_allclose(img[y, x, :3], want[i], atol=2.0)


def _box_objects(matrix, bits=16):
    from piste.world.objects import ObjectMesh, ObjectSet, _box, compress_mesh, normal_matrix, object_texture

    p, n, t, i = _box((0, 0, 0.5), (1.0, 1.0, 1.0), "metal")
    cm = compress_mesh(ObjectMesh("box", p, n, t, i), normal_bits=bits)
    m = np.asarray(matrix, float)[None]
    center = m[:, :3, 3] + m[0, :3, :3] @ [0, 0, 0.5]
    return ObjectSet({"box": cm}, ("box",), np.array([0]), m, normal_matrix(m), center, np.array([3.0]),
                     choose_lights_many(LIGHTS, center), object_texture()), (p, n)


def _scaled_matrix():
    a = np.radians(35.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    b = np.radians(-40.0)
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    m = np.eye(4)
    m[:3, :3] = np.diag([1.0, 2.5, 0.5]) @ rx @ rz  # rotate, then scale non-uniformly (a skewed box)
    m[:3, 3] = (0.3, -0.2, 0.0)
    return m


def test_object_normals_under_non_uniform_scale(gl):
    """Each face of a box under rotation x non-uniform scale is flat-lit with the inverse-transpose
    normal: its pixels match numpy's per-vertex light, and the plain matrix would not."""
    from piste.render.context import Offscreen
    from piste.render.object_pass import ObjectPass

    m = _scaled_matrix()
    objs, (p, n) = _box_objects(m)
    op = ObjectPass(gl, objs, LIGHTS)
    target = Offscreen(gl, (128, 128))
    try:
        cam = _ortho_camera(m[:3, 3] + m[:3, :3] @ [0, 0, 0.5], 5.0)
        vp = cam.view_projection()
        target.use()
        target.clear((0, 0, 0, 1))
        op.draw(vp, cam.eye, light_only=True)
        img = target.read()
    finally:
        op.release()
        target.release()
    vl = objs.lights[0]
    nmat = np.linalg.inv(m[:3, :3]).T
    checked = 0
    wrong_differs = False
    for f in range(6):
        fn = n[4 * f]
        wn = nmat @ fn
        wn /= np.linalg.norm(wn)
        if wn[2] < 0.2:  # faces the camera (looking down -z)?
            continue
        centre = p[4 * f: 4 * f + 4].mean(0)
        x, y = _pixel(vp, m[:3, :3] @ centre + m[:3, 3], 128, 128)
        want = np.clip(vertex_light(wn[None], vl)[0], 0, 1) * 255
        np.testing.assert_allclose(img[y, x, :3], want, atol=2.5)
        naive = m[:3, :3] @ fn
        naive /= np.linalg.norm(naive)
        if np.abs(np.clip(vertex_light(naive[None], vl)[0], 0, 1) * 255 - want).max() > 8:
            wrong_differs = True
        checked += 1
    assert checked >= 2 and wrong_differs


@pytest.mark.parametrize("mode", ["baked", "points"])
def test_object_lighting_modes_match_the_equation(gl, mode):
    """Baked RGBs and per-vertex point/spot lights reproduce shade() on flat faces."""
    from piste.lighting import PointLight, SpotLight, shade
    from piste.render.context import Offscreen
    from piste.render.object_pass import ObjectPass

    lights = LIGHTS + Lights((PointLight((1.5, 0.0, 2.0), (1.0, 0.5, 0.2), 0.6, range=30.0, falloff=0.0),
                              SpotLight((0.0, 0.0, 6.0), (0, 0, -1), (0.2, 1.0, 0.3), 0.5, range=50.0,
                                        inner_angle=40, outer_angle=60, falloff=0.0)))
    m = np.eye(4)
    m[:3, :3] = np.diag([2.0, 2.0, 0.5])
    objs, (p, n) = _box_objects(m)
    op = ObjectPass(gl, objs, lights, mode=mode)
    target = Offscreen(gl, (64, 64))
    try:
        cam = _ortho_camera((0, 0, 0.5), 3.0)
        vp = cam.view_projection()
        target.use()
        target.clear((0, 0, 0, 1))
        op.draw(vp, cam.eye, light_only=True)
        img = target.read()
    finally:
        op.release()
        target.release()
    top = 5  # the +z face (axis 2, sign +1)
    corners = p[4 * top: 4 * top + 4]
    # falloff 0 and a wide cone: light is constant across the face up to the Lambert direction
    centre = corners.mean(0)
    wp = m[:3, :3] @ centre + m[:3, 3]
    want = np.clip(shade(lights, wp[None], np.array([[0, 0, 1.0]]))[0], 0, 1) * 255
    x, y = _pixel(vp, wp, 64, 64)
    np.testing.assert_allclose(img[y, x, :3], want, atol=6.0)  # Gouraud across the face: a few steps


def test_rider_reference_image_and_specular(gl, reference_image):
    """The default rider in its ride pose, lit by known lights, textured, with the specular pass."""
    from piste.character import default_rider, make_lods
    from piste.character.skinning import BlendedMesh
    from piste.render.character_pass import CharacterPass, specular_map
    from piste.render.context import Offscreen
    from piste.world.camera import Camera

    model = default_rider(0)
    from piste.world.scene import orient_outward
    lods = make_lods(orient_outward(model.meshes[0])[0])
    pose = model.clips["ride"].sample(0.3, loop=True)
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # rider +Y up -> world +Z up
    skin = rot @ model.skeleton.skin_matrices(pose)
    bm = BlendedMesh(lods[0].palette, lods[0].mesh.positions, lods[0].mesh.normals)
    pos, nrm = bm.apply_many(skin[None])
    spec = specular_map(model.meshes[0].texture)
    assert spec[..., 0].max() == 255 and (spec[..., 0] > 0).mean() > 0.05
    cp = CharacterPass(gl, lods, model.meshes[0].texture, max_riders=1)
    target = Offscreen(gl, (96, 128))
    try:
        cam = Camera(eye=(1.2, -3.2, 1.4), target=(0, 0, 0.9), fov_y=40, aspect=96 / 128, near=0.1, far=50)
        vp = cam.view_projection()
        vl = choose_lights_many(LIGHTS, np.array([[0, 0, 1.0]]))
        cp.upload([(np.array([0]), pos, nrm), (np.zeros(0, int), pos[:0, :0], nrm[:0, :0]),
                   (np.zeros(0, int), pos[:0, :0], nrm[:0, :0])])
        images = []
        for specular in (False, True):
            target.use()
            target.clear((0.1, 0.1, 0.1, 1))
            cp.draw(vp, cam.eye, vl, sun=LIGHTS.direct[0], specular=specular)
            images.append(target.read())
    finally:
        cp.release()
        target.release()
    plain, shiny = (im[..., :3].astype(int) for im in images)
    assert (shiny >= plain).all()  # additive
    assert (shiny - plain).max() > 25 and ((shiny - plain).max(-1) > 8).mean() > 0.002
    covered = (plain != 26).any(-1).mean()
    assert 0.1 < covered < 0.6  # a person on a board fills part of the frame
    reference_image("scene_rider_lit", images[1])


def test_object_reference_image(gl, reference_image):
    from piste.render.context import Offscreen
    from piste.render.object_pass import ObjectPass
    from piste.world.objects import ObjectSet, compress_mesh, make_mesh, normal_matrix, object_texture

    kinds = ("tree", "sign", "rock", "rail")
    meshes = {k: compress_mesh(make_mesh(k)) for k in kinds}
    mats = np.tile(np.eye(4), (4, 1, 1))
    mats[0, :3, :3] = np.diag([0.5, 0.5, 0.35])
    mats[0, :3, 3] = (-2.5, 0, 0)
    a = np.radians(20)  # the sign graphic (-y face) towards the camera
    mats[1, :3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    mats[1, :3, 3] = (-0.5, 0, 0)
    mats[2, :3, :3] = np.diag([1.0, 0.7, 0.6])
    mats[2, :3, 3] = (1.2, 0, 0)
    mats[3, :3, 0] = (1.5, 0.0, 0.4)  # a sloped, sheared rail
    mats[3, :3, 3] = (2.4, -0.5, 0)
    centre = mats[:, :3, 3] + np.array([0, 0, 1.0])
    objs = ObjectSet(meshes, kinds, np.arange(4), mats, normal_matrix(mats), centre, np.full(4, 5.0),
                     choose_lights_many(LIGHTS, centre), object_texture())
    from piste.world.camera import Camera

    op = ObjectPass(gl, objs, LIGHTS)
    target = Offscreen(gl, (128, 64))
    try:
        cam = Camera(eye=(0.3, -7.0, 2.2), target=(0.0, 0.0, 1.0), fov_y=45, aspect=2.0, near=0.1, far=50)
        target.use()
        target.clear((0.8, 0.86, 0.93, 1))
        op.draw(cam.view_projection(), cam.eye)
        img = target.read()
    finally:
        op.release()
        target.release()
    assert op.drawn == 4
    reference_image("scene_objects", img)


def test_folded_specular_matches_the_second_pass(gl):
    """The riders' specular added by the base pass (``fold_specular``, the default) gives the talk's
    two-pass picture (lit pass, then the additive specular pass over the same depths) within a
    rounding step, in fog too; and it does add highlights."""
    from piste.character import default_rider, make_lods
    from piste.character.skinning import BlendedMesh
    from piste.render.character_pass import CharacterPass
    from piste.render.context import Offscreen
    from piste.world.camera import Camera
    from piste.world.scene import orient_outward

    model = default_rider(0)
    lods = make_lods(orient_outward(model.meshes[0])[0])
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    skins = []
    for k, t in enumerate((0.3, 0.7)):  # two riders, the second overlapping the first from behind
        m = rot @ model.skeleton.skin_matrices(model.clips["ride"].sample(t, loop=True))
        m[:, :3, 3] += (0.3 * k, 0.8 * k, 0.0)
        skins.append(m)
    bm = BlendedMesh(lods[0].palette, lods[0].mesh.positions, lods[0].mesh.normals)
    pos, nrm = bm.apply_many(np.stack(skins))
    cp = CharacterPass(gl, lods, model.meshes[0].texture, max_riders=2)
    target = Offscreen(gl, (96, 128))
    empty = (np.zeros(0, int), pos[:0], nrm[:0])
    try:
        cam = Camera(eye=(1.2, -3.2, 1.4), target=(0, 0, 0.9), fov_y=40, aspect=96 / 128, near=0.1, far=50)
        vp = cam.view_projection()
        vl = choose_lights_many(LIGHTS, np.array([[0, 0, 1.0], [0.3, 0.8, 1.0]]))
        cp.upload([(np.array([0, 1]), pos, nrm), empty, empty])
        out = {}
        for fog in (None, (0.8, 0.86, 0.93, 0.08)):
            for fold, specular in ((True, True), (False, True), (True, False)):
                cp.fold_specular = fold
                target.use()
                target.clear((0.1, 0.1, 0.1, 1))
                cp.draw(vp, cam.eye, vl, sun=LIGHTS.direct[0], fog=fog, specular=specular)
                out[fog is not None, fold, specular] = target.read()[..., :3].astype(int)
    finally:
        cp.release()
        target.release()
    for fogged in (False, True):
        one, two, plain = out[fogged, True, True], out[fogged, False, True], out[fogged, True, False]
        assert np.abs(one - two).max() <= 1  # one rounding instead of two
        assert (one - plain).max() > 25  # the highlights are there
