"""Fuzz piste's own glTF output re-imported: files written by export_gltf in a session fixture (a
scene .glb: terrain with light map and base texture, instanced objects (EXT_mesh_gpu_instancing),
lights, cameras; a rider .gltf + .bin: skeleton, skin, morphs, one clip; the same scene with
instancing as nodes), mutated byte-wise and structurally (fields of the wrong type, huge counts,
offsets past the buffer, hostile URIs) and loaded with load_gltf.  Each case loads or raises a
PisteError naming the file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from fuzzlib import byte_mutations, check, doc_mutations, dump_json, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from piste.character import default_rider
from piste.scene_data import Camera, DirectionalLight, SpotLight
from piste.formats.gltf import load_gltf
from piste.formats.gltf_export import CharacterExport, ObjectsExport, TerrainExport, export_gltf
from piste.terrain.net import PatchNet
from piste.terrain.tessellate import terrain_mesh


def _net(n=2):
    g = np.zeros((3 * n + 1, 3 * n + 1, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(3 * n + 1.0), np.arange(3 * n + 1.0))
    g[..., 2] = 0.3 * np.sin(g[..., 0] / 3) + 0.1 * g[..., 1]
    return PatchNet.from_control_grid(g)


def _objects():
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    quad = (np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1.0]]), np.tile([0, -1.0, 0], (4, 1)),
            np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]]), tri)
    mats = np.tile(np.eye(4), (3, 1, 1))
    mats[:, :3, 3] = [[1, 2, 0], [3, 1, 0], [5, 5, 1]]
    return ObjectsExport({"a": quad, "b": quad}, ("a", "b"), np.array([0, 1, 0]), mats, np.full((4, 4, 4), 90, np.uint8))


@pytest.fixture(scope="session")
def exported(tmp_path_factory):
    """{name: path} of piste-written glTF files."""
    from piste.render.textures import lightmap_atlas_size

    d = tmp_path_factory.mktemp("export")
    net = _net()
    w, h = lightmap_atlas_size(net, 4)
    atlas = np.random.default_rng(1).uniform(0.0, 1.2, (h, w, 3)).astype(np.float32)
    lights = [DirectionalLight(direction=(0.3, 0.4, -0.8), color=(1.0, 0.9, 0.8), intensity=1.2, name="sun"),
              SpotLight(position=(1.0, 2.0, 30.0), direction=(0.0, 0.1, -1.0), color=(0.2, 0.5, 1.0), intensity=0.9,
                        range=60.0, inner_angle=11.5, outer_angle=28.6, name="spot")]
    cams = [Camera(np.array([10.0, -20.0, 15.0]), np.array([10.0, -19.2, 14.4]), fov_y=51.6, aspect=1.5, near=0.5,
                   far=900.0, name="c")]
    terrain = TerrainExport(terrain_mesh(net, 4), atlas, np.full((4, 4, 4), 200, np.uint8))
    export_gltf(d / "scene.glb", terrain=terrain, objects=_objects(), lights=lights, cameras=cams)
    export_gltf(d / "nodes.gltf", terrain=TerrainExport(terrain_mesh(net, 4)), objects=_objects(), instancing="nodes")
    rider = default_rider(seed=0)
    export_gltf(d / "rider.gltf", characters=[CharacterExport(rider, name="rider", clips=sorted(rider.clips)[:1])])
    return {p.name: p for p in (d / "scene.glb", d / "nodes.gltf", d / "rider.gltf")}


KINDS = ["scene.glb", "nodes.gltf", "rider.gltf"]


def _glb_parts(data: bytes):
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + jlen])
    rest = data[20 + jlen:]
    return doc, (rest[8:] if len(rest) >= 8 else None)


def _glb(doc_bytes: bytes, blob) -> bytes:
    doc_bytes += b" " * (-len(doc_bytes) % 4)
    body = struct.pack("<II", len(doc_bytes), 0x4E4F534A) + doc_bytes
    if blob is not None:
        body += struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def _target(exported, name, tmp_path_factory):
    """A fresh folder with the seed's files (the .bin beside a .gltf); the seed's path in it."""
    d = tmp_path_factory.mktemp("m")
    seed = exported[name]
    for p in seed.parent.glob(seed.stem + ".*"):
        (d / p.name).write_bytes(p.read_bytes())
    return d / name


@pytest.mark.parametrize("name", KINDS)
def test_seeds_load(exported, name):
    assert check(load_gltf, exported[name], "export seeds") == "loaded"


@pytest.mark.parametrize("name", KINDS)
@given(data=st.data())
@fuzz_settings(8)
def test_export_bytes(exported, tmp_path_factory, name, data):
    """The .glb, the .gltf's JSON or its .bin mutated byte-wise."""
    target = _target(exported, name, tmp_path_factory)
    victim = target if target.suffix == ".glb" or data.draw(st.booleans()) else target.with_suffix(".bin")
    victim.write_bytes(data.draw(byte_mutations(victim.read_bytes())))
    check(load_gltf, target, "export byte-wise", names=target.stem)  # the model or its .bin


@pytest.mark.parametrize("name", KINDS)
@given(data=st.data())
@fuzz_settings(15)
def test_export_structure(exported, tmp_path_factory, name, data):
    target = _target(exported, name, tmp_path_factory)
    raw = target.read_bytes()
    if target.suffix == ".glb":
        doc, blob = _glb_parts(raw)
        target.write_bytes(_glb(dump_json(data.draw(doc_mutations(doc))), blob))
    else:
        target.write_bytes(dump_json(data.draw(doc_mutations(json.loads(raw)))))
    check(load_gltf, target, "export structural")
