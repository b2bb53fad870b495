"""``piste export`` on built scenes: the Khronos validator, piste's own re-import and Blender
(headless) all read back what piste wrote."""

from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))  # for `from gltf_tools import ...`
from gltf_tools import assert_valid, blender_import  # noqa: E402

from piste.cli import main  # noqa: E402
from piste.formats.gltf.units import light_to_gltf, lights_without_gltf_form  # noqa: E402
from piste.commands.render import load_or_build  # noqa: E402
from piste.formats.gltf import load_gltf  # noqa: E402

SCENES = Path(__file__).resolve().parents[2] / "examples" / "scenes"
TO_GLTF = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])

SCENE = """\
name = "small"

[terrain]
source = "hill.npz"

[lightmap]
res = 8

[visibility]
cell = 64.0

[[riders]]
name = "rider"
position = [60.0, 60.0]
clip = "ride"

[[riders]]
name = "other"
position = [70.0, 50.0]
clip = "spin"
phase = 0.25

[[objects]]
model = "builtin:tree"
position = [70.0, 70.0]

[[objects]]
model = "builtin:tree"
position = [50.0, 80.0]
scale = 1.5

[[objects]]
model = "builtin:rock"
position = [40.0, 90.0]

[[lights]]
type = "ambient"
color = [0.5, 0.6, 0.8]
intensity = 0.4

[[lights]]
type = "directional"
direction = [0.3, 0.6, -0.6]
color = [1.0, 0.9, 0.8]
intensity = 1.0

[[lights]]
type = "point"
position = [64.0, 64.0, 40.0]
color = [1.0, 0.6, 0.3]
intensity = 0.8
range = 30.0
falloff = 2.0

[[lights]]
type = "spot"
position = [30.0, 30.0, 50.0]
direction = [0.5, 0.5, -0.7]
intensity = 1.2
range = 60.0
inner_angle = 15.0
outer_angle = 25.0

[[lights]]
type = "point"
position = [20.0, 100.0, 30.0]
intensity = -0.5
range = 20.0

[[cameras]]
name = "main"
eye = [64.0, -20.0, 60.0]
target = [64.0, 64.0, 20.0]
"""


@pytest.fixture(scope="module")
def small_bundle(tmp_path_factory):
    d = tmp_path_factory.mktemp("scene")
    n, spacing = 33, 4.0
    y, x = np.mgrid[0:n, 0:n] * spacing
    z = 30.0 - 0.3 * y + 3.0 * np.sin(x / 15.0) + 2.0 * np.cos(y / 9.0)
    np.savez(d / "hill.npz", z=z, dx=np.float64(spacing))
    (d / "small.toml").write_text(SCENE)
    load_or_build(d / "small.toml")
    return d / "small.piste"


def test_cli_export_forms_validate(small_bundle, tmp_path, capsys):
    outs = []
    for args in ([], ["--instancing", "nodes"], ["--level", "camera:main"], ["--level", "8", "--no-base-texture"]):
        out = tmp_path / f"s{len(outs)}{'.gltf' if len(outs) % 2 else '.glb'}"
        assert main(["export", str(small_bundle), str(out), "--quiet", *args]) == 0
        assert "2 riders" in capsys.readouterr().out
        outs.append(out)
    assert_valid(*outs)
    # errors are one line, exit status 2, no file left behind
    assert main(["export", str(small_bundle), str(tmp_path / "bad.glb"), "--level", "5"]) == 1
    assert "--level must be 4, 6, 8 or camera:NAME" in capsys.readouterr().err
    assert main(["export", str(small_bundle), str(tmp_path / "bad.glb"), "--level", "camera:nope"]) == 1
    assert "no camera 'nope'" in capsys.readouterr().err
    assert not (tmp_path / "bad.glb").exists()


def test_reimport_matches_the_bundle(small_bundle, tmp_path):
    """load_gltf on the export: riders' bind-space meshes, skins and clips as float32, objects,
    lights back to piste's units, cameras."""
    from piste.pipeline.gltf_import import GltfCameras

    b = load_or_build(small_bundle)
    out = tmp_path / "s.glb"
    assert main(["export", str(small_bundle), str(out), "--quiet", "--instancing", "nodes"]) == 0
    back = load_gltf(out)
    model = b.rider_model()
    src = model.meshes[0]
    for r, clip in (("rider", "ride"), ("other", "spin")):
        m = next(x for x in back.meshes if x.name == f"{r}:{src.group}")
        assert np.array_equal(m.positions, src.positions) and np.array_equal(m.indices, src.indices)
        assert src.n_morphs > 0 and m.morph_names == src.morph_names and np.allclose(m.morph_positions, src.morph_positions, atol=1e-7)
        names = np.array(back.skeleton.names)
        live = src.weights > 0
        assert np.array_equal(names[m.joints.astype(int)][live],
                              np.char.add(f"{r}:", np.array(model.skeleton.names)[src.joints.astype(int)])[live])
        c0, c1 = model.clips[clip], back.clips[f"{r}:{clip}"]
        for bone, tracks in c0.tracks.items():
            for path, tr in tracks.items():
                t1 = c1.tracks[f"{r}:{bone}"][path]
                assert np.array_equal(t1.times, tr.times.astype(np.float32))
                assert np.allclose(t1.values, tr.values.astype(np.float32), atol=1e-6)
        # world placement: root bone world = TO_GLTF @ rider matrix @ rest
        i = [m_["name"] for m_ in b.manifest["riders"]].index(r)
        root = model.skeleton.names[0]
        w = back.skeleton.world_matrices()[back.skeleton.bone_index(f"{r}:{root}")]
        want = b.arrays["riders/matrix"][i] @ model.skeleton.world_matrices()[0]
        assert np.allclose(w[:3, 3], TO_GLTF @ want[:3, 3], atol=1e-3)
    # objects: one node each (plain-node fallback)
    objs = b.objects()
    assert sum(1 for x in back.meshes if x.group in objs.kinds) == len(objs.kind)
    # lights: the reader gives piste's lights back (the negative one left out)
    lights = back.lights
    direct = [x for x in b.lights.direct if x.intensity >= 0]
    assert len(lights) == len(direct) == 3
    for a, c in zip(direct, lights):
        assert type(a) is type(c) and math.isclose(a.intensity, c.intensity, rel_tol=1e-6)
        if hasattr(a, "range"):
            assert math.isclose(a.range, c.range, rel_tol=1e-6)
            assert np.allclose(a.position, c.position, atol=1e-4)
        if hasattr(a, "direction"):
            d = np.asarray(a.direction) / np.linalg.norm(a.direction)
            assert np.allclose(d, c.direction, atol=1e-6)
        if hasattr(a, "outer_angle"):
            assert math.isclose(a.outer_angle, c.outer_angle, rel_tol=1e-6)
    other = lights_without_gltf_form(b.lights)
    assert len(other["ambient"]) == 1 and len(other["negative"]) == 1
    cams = GltfCameras.from_file(back.cameras)
    c0 = b.camera("main")
    assert np.allclose(cams["main"].eye, c0.eye, atol=1e-4) and math.isclose(cams["main"].fov_y, c0.fov_y, rel_tol=1e-6)
    f0 = (c0.target - c0.eye) / np.linalg.norm(c0.target - c0.eye)
    f1 = (cams["main"].target - cams["main"].eye) / 10.0
    assert np.allclose(f0, f1, atol=1e-6)


@pytest.mark.slow
def test_blender_imports_the_default_scene(tmp_path):
    """Blender 3.x (Debian's package, headless) imports the default scene's export: the terrain,
    every rider as an armature-deformed mesh with its action, the lights with Blender's own unit
    conversion, the cameras, all at piste's coordinates."""
    from piste.pipeline.build import build_scene
    from piste.world.scene_file import load_scene

    work = tmp_path / "scenes"
    shutil.copytree(SCENES, work, ignore=shutil.ignore_patterns("*.piste", ".piste-cache"))
    scene = load_scene(work / "default.toml")
    scene.lightmap.shadows = False  # keep the big course fast
    scene.visibility.cell = 250.0
    r = build_scene(scene, out=tmp_path / "default.piste")
    out = tmp_path / "default.glb"
    assert main(["export", str(r.path), str(out), "--quiet", "--instancing", "nodes"]) == 0
    assert_valid(out)
    b = load_or_build(r.path)
    seen = blender_import(out, tmp_path)

    from piste.formats.gltf.units import camera_to_gltf
    from piste.terrain.tessellate import terrain_mesh

    tm = terrain_mesh(b.net, 4)
    t = seen["meshes"]["terrain"]
    assert (t["vertices"], t["polygons"]) == (tm.n_vertices, tm.n_triangles) and len(t["uv_layers"]) == 2
    assert np.allclose(t["world_min"], tm.positions.min(0), atol=1e-2)
    assert np.allclose(t["world_max"], tm.positions.max(0), atol=1e-2)
    model = b.rider_model()
    riders = b.manifest["riders"]
    assert set(seen["armatures"]) == {r_["name"] for r_ in riders}
    for i, rd in enumerate(riders):
        arm = seen["armatures"][rd["name"]]
        assert arm["bones"] and set(arm["bones"]) == {f"{rd['name']}:{n}" for n in model.skeleton.names}
        mesh = seen["meshes"][f"{rd['name']}:{model.meshes[0].group}"]
        assert mesh["armature"] == rd["name"] and mesh["polygons"] == model.meshes[0].n_triangles
        assert mesh["shape_keys"][1:] == list(model.meshes[0].morph_names)  # "Basis" first, then the morphs
        # bone heads at the rider's placement (Blender's bones start at the joints)
        wm = b.arrays["riders/matrix"][i] @ model.skeleton.world_matrices()
        for j, n in enumerate(model.skeleton.names):
            assert np.allclose(arm["heads"][f"{rd['name']}:{n}"], wm[j, :3, 3], atol=1e-3)
        act = [k for k in seen["actions"] if k.startswith(f"{rd['name']}:{rd['clip']}")]
        assert len(act) == 1, seen["actions"].keys()
        a = seen["actions"][act[0]]
        clip = model.clips[rd["clip"]]
        assert set(a["bones"]) == {f"{rd['name']}:{n}" for n in clip.tracks}
        assert math.isclose(a["frame_range"][1] / 24.0, clip.duration, rel_tol=0.05)
    objs = b.objects()
    assert sum(1 for k in seen["meshes"] if k not in ("terrain",) and ":" not in k) == len(objs.kind)
    lights = [d for d in (light_to_gltf(x, 683.0, i) for i, x in enumerate(b.lights)) if d is not None]
    assert set(seen["lights"]) == {x["name"] for x in lights}
    for x in lights:
        s = seen["lights"][x["name"]]
        assert s["type"] == {"directional": "SUN", "point": "POINT", "spot": "SPOT"}[x["type"]]
        want = x["intensity"] / 683.0 * (1.0 if x["type"] == "directional" else 4 * math.pi)
        assert math.isclose(s["energy"], want, rel_tol=1e-4)
        if x["type"] != "directional":
            assert np.allclose(s["location"], x["position"], atol=1e-3)
        if x["type"] != "point":
            assert np.allclose(s["direction"], x["direction"] / np.linalg.norm(x["direction"]), atol=1e-4)
    cams = {name: camera_to_gltf(c) for name, c in b.cameras.items()}
    assert set(seen["cameras"]) == set(cams)
    for name, c in cams.items():
        s = seen["cameras"][name]
        assert np.allclose(s["location"], c["position"], atol=1e-3)
        assert np.allclose(s["direction"], c["forward"], atol=1e-4)
        assert math.isclose(s["clip_start"], c["znear"], rel_tol=1e-5)
