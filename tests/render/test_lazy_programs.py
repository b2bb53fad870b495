"""Programs a frame may never use are compiled on first use, not at set-up (a fresh process with an
empty Mesa shader cache paid llvmpipe ~4 ms for each): the riders' plain base and separate
specular passes, the objects' generic program, the mip-level program where compute shaders draw
the levels.  Each still draws when asked for (its pictures: tests/render/test_scene_passes.py,
test_object_programs.py, test_mip_chain.py).  Also the light-map atlas upload's range checks."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.lighting import AmbientLight, DirectionalLight, Lights
from piste.lighting.vertex import choose_lights_many

LIGHTS = Lights((AmbientLight((0.3, 0.3, 0.35)), DirectionalLight((0.4, 0.3, -0.8), (1.0, 0.95, 0.9), 1.0)))


def _rider(gl):
    from piste.character import default_rider, make_lods
    from piste.character.skinning import BlendedMesh
    from piste.render.character_pass import CharacterPass
    from piste.world.scene import orient_outward

    model = default_rider(0)
    lods = make_lods(orient_outward(model.meshes[0])[0])
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    skin = rot @ model.skeleton.skin_matrices(model.clips["ride"].sample(0.3, loop=True))
    pos, nrm = BlendedMesh(lods[0].palette, lods[0].mesh.positions, lods[0].mesh.normals).apply_many(skin[None])
    cp = CharacterPass(gl, lods, model.meshes[0].texture, max_riders=1)
    empty = (np.zeros(0, int), pos[:0], nrm[:0])
    cp.upload([(np.array([0]), pos, nrm), empty, empty])
    return cp


def test_rider_programs_compiled_when_first_drawn(gl):
    from piste.render.context import Offscreen
    from piste.world.camera import Camera

    cp = _rider(gl)
    target = Offscreen(gl, (48, 64))
    try:
        assert cp._prog is None and cp._prog_spec is None and cp._prog_lit is None  # nothing at set-up
        cam = Camera(eye=(1.2, -3.2, 1.4), target=(0, 0, 0.9), fov_y=40, aspect=48 / 64, near=0.1, far=50)
        vl = choose_lights_many(LIGHTS, np.array([[0, 0, 1.0]]))
        images = {}
        for fold, specular in ((True, True), (True, False), (False, True)):
            cp.fold_specular = fold
            target.use()
            target.clear((0.1, 0.1, 0.1, 1))
            cp.draw(cam.view_projection(), cam.eye, vl, sun=LIGHTS.direct[0], specular=specular)
            images[fold, specular] = target.read()[..., :3].astype(int)
            if (fold, specular) == (True, True):  # the default frame: the lit program alone
                assert cp._prog_lit is not None and cp._prog is None and cp._prog_spec is None
        assert cp._prog is not None and cp._prog_spec is not None  # made when those passes came
        assert cp.prog is cp._prog and cp.prog_spec is cp._prog_spec  # once
        plain = images[True, False]
        assert (plain != 26).any(-1).mean() > 0.05  # the rider was drawn by the plain program
        assert (images[False, True] >= plain).all() and (images[False, True] > plain).any()  # and the extra pass
        assert np.abs(images[True, True] - images[False, True]).max() <= 2  # folded = two passes
    finally:
        cp.release()
        target.release()
    fresh = _rider(gl)
    fresh.release()  # nothing compiled: released all the same


def test_object_generic_program_compiled_when_asked_for(gl):
    from piste.render.context import Offscreen
    from piste.render.object_pass import ObjectPass
    from piste.world.camera import Camera
    from piste.world.objects import ObjectSet, compress_mesh, make_mesh, normal_matrix, object_texture

    kinds = ("tree", "rock")
    meshes = {k: compress_mesh(make_mesh(k)) for k in kinds}
    mats = np.tile(np.eye(4), (2, 1, 1))
    mats[:, :3, 3] = [(-1.0, 0, 0), (1.0, 0, 0)]
    centre = mats[:, :3, 3] + [0, 0, 1.0]
    objs = ObjectSet(meshes, kinds, np.arange(2), mats, normal_matrix(mats), centre, np.full(2, 5.0),
                     choose_lights_many(LIGHTS, centre), object_texture())
    op = ObjectPass(gl, objs, LIGHTS)
    target = Offscreen(gl, (64, 32))
    cam = Camera(eye=(0.3, -7.0, 2.2), target=(0.0, 0.0, 1.0), fov_y=45, aspect=2.0, near=0.1, far=50)
    images = []
    try:
        assert op._programs == {}  # nothing compiled at set-up
        for specialised in (True, False):
            op.specialised = specialised
            target.use()
            target.clear((0.8, 0.86, 0.93, 1))
            op.draw(cam.view_projection(), cam.eye)
            images.append(target.read()[..., :3].astype(int))
            assert ((None, False) in op._programs) == (not specialised)  # the generic one only when drawn with
        assert op.prog is op._programs[None, False][0]
    finally:
        op.release()
        target.release()
    assert op.drawn == 2 and (images[0] != images[0][0, 0]).any(-1).mean() > 0.05
    assert np.abs(images[0] - images[1]).max() <= 2


def test_mip_levels_program_compiled_at_the_first_build(gl):
    from piste.render.textures import MipLevels

    tex = gl.texture((16, 16), 4)
    mips = MipLevels(gl, tex, 2)
    try:
        assert mips._prog is None and mips._vao is None
        img = np.random.default_rng(0).integers(0, 256, (16, 16, 4), dtype=np.uint8)
        tex.write(img.tobytes())
        mips.build()
        assert mips._prog is not None and mips.vao is mips._vao  # (the levels it draws: test_mip_chain.py)
    finally:
        mips.release()
        tex.release()
    unused = gl.texture((8, 8), 4)
    MipLevels(gl, unused, 1).release()  # never built: released all the same
    unused.release()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_light_map_atlas_must_be_finite(gl, bad):
    from piste.render.terrain_pass import TerrainPass

    tp = TerrainPass(gl, lightmap=None)
    try:
        atlas = np.ones((4, 4, 3), np.float32)
        atlas[2, 1, 0] = bad
        with pytest.raises(RenderError, match="finite"):
            tp.set_lightmap(atlas)
    finally:
        tp.release()


def test_light_map_atlas_clipped_to_the_half_float_range(gl):
    """Texels below 0 or above 65000 are clipped; in range (float or uint8, half-bright or not) they
    are uploaded as half floats unchanged."""
    from piste.render.terrain_pass import TerrainPass

    tp = TerrainPass(gl, lightmap=None)
    try:
        atlas = np.linspace(0.0, 2.0, 4 * 4 * 3, dtype=np.float32).reshape(4, 4, 3)
        for a, want in ((atlas, atlas), (atlas * 1e5 - 3.0, np.clip(atlas * 1e5 - 3.0, 0.0, 65000.0)),
                        (np.dstack([atlas, np.full((4, 4), -1.0, np.float32)]), atlas)):
            tp.set_lightmap(a)
            got = np.frombuffer(tp.light.read(), np.float16).reshape(4, 4, 3)
            assert np.array_equal(got, want.astype(np.float16))
        raw = np.arange(48, dtype=np.uint8).reshape(4, 4, 3) * 5
        for half in (False, True):
            tp.set_lightmap(raw, half_bright=half)
            got = np.frombuffer(tp.light.read(), np.float16).reshape(4, 4, 3)
            assert np.array_equal(got, (raw / (128.0 if half else 255.0)).astype(np.float32).astype(np.float16))
    finally:
        tp.release()


@pytest.mark.parametrize("soft", [False, True])
def test_gathered_receiver_program_compiled_when_first_used(gl, soft):
    """The shadow receivers' program over gathered vertices is made at first use (a frame over the
    resident terrain draws only the resident one), with the uniforms set before it existed."""
    from piste.render.shadow_pass import ShadowPass

    sp = ShadowPass(gl, n_max=1, tile=64, soft=soft)
    try:
        assert sp._receiver is None  # nothing at set-up
        sp.set_sunlight(np.ones((4, 4), np.float32), (-10.0, -20.0, 30.0, 40.0))
        assert sp._receiver is None
        p = sp.receiver
        assert p is sp._receiver and sp.receiver is p  # made once
        assert p["u_sun_rect"].value == pytest.approx((-10.0, -20.0, 40.0, 60.0))
        assert p["u_sunlit"].value == 4 and p["u_shadow"].value == 3
        sp.set_sunlight(np.ones((4, 4), np.float32), (0.0, 0.0, 1.0, 2.0))  # later changes reach it
        assert p["u_sun_rect"].value == pytest.approx((0.0, 0.0, 1.0, 2.0))
    finally:
        sp.release()


def test_released_before_receiver_program_made(gl):
    from piste.render.shadow_pass import ShadowPass

    ShadowPass(gl, n_max=1, tile=64).release()  # (no gathered receiver program to release)


@pytest.mark.parametrize("name", ["shadow_receiver.frag.glsl", "shadow_receiver_soft.frag.glsl"])
def test_receiver_fragment_shaders_read_all_of_v_world(name):
    """Both receiver fragment shaders read v_world's three components (z times a factor that is
    exactly 1): their interpolated inputs are then the terrain's and the objects' (two full vec4
    slots), and llvmpipe reuses those programs' triangle-setup function instead of compiling one
    more at the receivers' first draw (it keeps no setup function in its shader cache)."""
    from piste.render.context import load_shader

    code = "\n".join(line.split("//")[0] for line in load_shader(name).splitlines())
    assert "in vec3 v_world;" in code and "v_world.xy" in code
    assert "step(-3.0e38, v_world.z)" in code


def _fragment_inputs(name: str) -> list[str]:
    from piste.render.context import load_shader

    code = "\n".join(line.split("//")[0] for line in load_shader(name).splitlines())
    return [line.split()[-2] for line in code.splitlines() if line.strip().startswith(("in ", "flat in "))]


@pytest.mark.parametrize("name", ["shadow_caster.frag.glsl", "shadow_caster_soft.frag.glsl", "sky.frag.glsl"])
def test_caster_and_sky_fragment_shaders_take_the_receivers_inputs(name):
    """The shadow casters' and the sky's fragment shaders read two interpolated vec3s (the extra one
    times a factor exactly 1), the receivers' set of inputs, which llvmpipe packs as the terrain's and
    the objects' (two vec4 slots, all read): it reuses one triangle-setup function for all of them
    rather than compiling one more at each first draw.  (Their pictures: tests/render/test_soft_shadows.py,
    the other shadow tests and the sky's.)"""
    from piste.render.context import load_shader

    assert _fragment_inputs(name) == _fragment_inputs("shadow_receiver_soft.frag.glsl") == ["vec3", "vec3"]
    assert "step(-3.0e38, min(" in load_shader(name) and "v_setup.z" in load_shader(name)
    vs = load_shader("sky.vert.glsl" if name.startswith("sky") else "shadow_caster.vert.glsl")
    assert "v_setup = " in vs
