"""Rider textures from SSX ``.ssh`` banks: the encoder writes the rider's texture as a bank beside the
.mpf, the decoder applies a bank (by the material's texture id, else by index), several materials
are packed into one texture, the scene key ``texture`` and the render shows the bank's colours."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from piste.cli import main
from piste.formats.ssx.mpf import mpf_bytes, parse_mpf, read_mpf, write_mpf
from piste.formats.ssx.mpf_encode import model_to_mpf
from piste.formats.ssx.mpf_model import mpf_partners, mpf_to_model
from piste.formats.ssx.ssh import SshBank, SshImage, read_ssh, write_ssh
from piste.pipeline.ssx_rider import apply_texture_banks, load_mpf_rider


SCENE = """\
[terrain]
source = "hill.npz"

[lightmap]
res = 4

[visibility]
cell = 32.0

[[riders]]
model = "ssx:RIDER.mpf"
texture = "{colour}.ssh"
position = [60.0, 60.0]
clip = "ride"

[[lights]]
type = "ambient"
color = [1.0, 1.0, 1.0]
intensity = 0.6

[[lights]]
type = "directional"
direction = [0.3, 0.6, -0.6]
intensity = 0.8

[[cameras]]
name = "close"
eye = [60.0, 56.0, 13.0]
target = [60.0, 60.0, 12.2]
"""


def _flat_bank(path, colours: dict):
    """A bank of 16 x 16 single-colour 8-bit images ``{name: (r, g, b)}`` (stored half-bright)."""
    ims = []
    for name, c in colours.items():
        pal = np.array([[(c[0] + 1) // 2, (c[1] + 1) // 2, (c[2] + 1) // 2, 128]], np.uint8)
        ims.append(SshImage(name, 2, np.zeros((16, 16), np.uint8), pal, long_name=""))
    write_ssh(SshBank(ims), path)
    return path


@pytest.fixture(scope="module")
def encoded(tmp_path_factory):
    d = tmp_path_factory.mktemp("tex")
    assert main(["mpf", "encode", str(d / "RIDER.mpf"), "--report", str(d / "r.json")]) == 0
    return d


def test_encode_writes_the_texture_bank(encoded, tmp_path):
    import json

    from piste.character import default_rider

    bank = read_ssh(encoded / "RIDER.ssh")
    assert [im.name for im in bank.images] == ["suit"] and bank[0].kind == 2 and len(bank[0].palette) <= 256
    want = default_rider(0).meshes[0].texture
    got = bank[0].rgba()
    assert got.shape == want.shape and np.abs(got.astype(int) - want.astype(int)).mean() < 2.0
    rep = json.loads((encoded / "r.json").read_text())["texture"]
    assert rep["size"] == [128, 128] and rep["mean_error"] < 2.0
    assert main(["mpf", "encode", str(tmp_path / "N.mpf"), "--ratios", "0.25", "--no-texture"]) == 0
    assert (tmp_path / "N.mpf").is_file() and not (tmp_path / "N.ssh").exists()


def test_encoder_quantises_many_colours_to_256():
    from dataclasses import replace

    from piste.character import default_rider
    from piste.formats.ssx.mpf_encode import texture_bank

    r = default_rider(0)
    tex = np.random.default_rng(1).integers(0, 256, (100, 60, 4), dtype=np.uint8)
    tex[..., 3] = 255
    bank, rep = texture_bank(replace(r, meshes=[replace(r.meshes[0], texture=tex)]))
    assert bank[0].pixels.shape == (128, 64) and 64 < len(bank[0].palette) <= 256
    assert rep["colours"] == len(bank[0].palette)
    assert rep["size"] == [64, 128] and rep["source_size"] == [60, 100] and 0 < rep["mean_error"] < 60


def test_decoded_rider_takes_the_bank_beside_it(encoded):
    plain = mpf_to_model(read_mpf(encoded / "RIDER.mpf"))
    r = load_mpf_rider(encoded / "RIDER.mpf")  # RIDER.ssh found beside it
    img = read_ssh(encoded / "RIDER.ssh")[0].rgba()
    assert plain.meshes[0].texture is None and plain.materials == [("suit", 0)]
    assert len(r.meshes) == 1 and np.array_equal(r.meshes[0].texture, img)
    assert all(np.array_equal(lod.mesh.texture, img) for lod in r.lods)
    assert np.array_equal(r.meshes[0].uv, plain.meshes[0].uv)  # one material: UVs as stored (tiling kept)


def test_material_finds_its_image_by_name_then_by_index(encoded, tmp_path):
    f = read_mpf(encoded / "RIDER.mpf")
    named = parse_ssh_bank(_flat_bank(tmp_path / "a.ssh", {"boot": (0, 0, 255), "suit": (255, 0, 0)}))
    m = apply_texture_banks(mpf_to_model(f), [named])
    assert tuple(m.meshes[0].texture[0, 0, :3]) == (255, 0, 0)  # "suit", the second image
    other = parse_ssh_bank(_flat_bank(tmp_path / "b.ssh", {"0000": (0, 255, 0), "0001": (255, 0, 0)}))
    m = apply_texture_banks(mpf_to_model(f), [other])
    assert tuple(m.meshes[0].texture[0, 0, :3]) == (0, 255, 0)  # no "suit": material 0 -> image 0
    assert any("textured by index" in n for n in m.notes)


def parse_ssh_bank(path):
    return read_ssh(path)


def test_two_materials_are_packed_into_one_texture(encoded, tmp_path):
    """Morph-group triangles given a second material (``boot``): each vertex samples its own
    material's image in the packed texture, in the top meshes and in every LOD."""
    f = parse_mpf(mpf_bytes(read_mpf(encoded / "RIDER.mpf")))
    for s in f.models:
        mats = np.zeros(2, s.materials.dtype)
        mats[0] = s.materials[0]
        mats["textures"][1, 0] = np.void(b"boot")
        s.materials = mats
        for g in s.groups:
            if g.type == 256:
                g.material = 1
    write_mpf(f, tmp_path / "TWO.mpf")
    _flat_bank(tmp_path / "TWO.ssh", {"suit": (255, 0, 0), "boot": (0, 0, 255)})
    r = load_mpf_rider(tmp_path / "TWO.mpf")
    assert r.materials == [("suit", 0), ("boot", 1)]
    tex = r.meshes[0].texture
    h, w = tex.shape[:2]
    for mesh, mat in [(r.meshes[0], r.mesh_materials[0])] + [(lod.mesh, m) for lod, m in zip(r.lods, r.lod_materials)]:
        assert mesh.texture is tex and set(np.unique(mat)) == {0, 1}
        px = tex[np.clip((mesh.uv[:, 1] * h).astype(int), 0, h - 1), np.clip((mesh.uv[:, 0] * w).astype(int), 0, w - 1)]
        assert np.all(px[mat == 0, 0] == 255) and np.all(px[mat == 0, 2] == 0)
        assert np.all(px[mat == 1, 2] == 255) and np.all(px[mat == 1, 0] == 0)


def test_partners_and_scene_key(encoded, tmp_path):
    from piste.errors import PisteError
    from piste.world.scene_file import loads_scene

    shutil.copy(encoded / "RIDER.mpf", tmp_path / "mac_body.mpf")
    shutil.copy(encoded / "RIDER.mpf", tmp_path / "mac_head.mpf")
    shutil.copy(encoded / "RIDER.ssh", tmp_path / "mac_head.ssh")
    _flat_bank(tmp_path / "red.ssh", {"suit": (255, 0, 0)})
    head, banks = mpf_partners(tmp_path / "mac_body.mpf")
    assert head == tmp_path / "mac_head.mpf" and banks == [tmp_path / "mac_head.ssh"]
    assert mpf_partners(tmp_path / "mac_body.mpf", tmp_path / "red.ssh")[1] == [tmp_path / "red.ssh"]
    np.savez(tmp_path / "hill.npz", z=np.zeros((9, 9)), dx=np.float64(4.0))
    text = ('[terrain]\nsource = "hill.npz"\n\n[[riders]]\nmodel = "{m}"\nposition = [10.0, 10.0]\n{t}\n')
    s = loads_scene(text.format(m="ssx:mac_body.mpf", t='texture = "red.ssh"'), tmp_path / "s.toml")
    assert s.riders[0].texture == str((tmp_path / "red.ssh").resolve())
    files = s.source_files()
    assert (tmp_path / "mac_head.mpf").resolve() in files and (tmp_path / "red.ssh").resolve() in files
    s = loads_scene(text.format(m="ssx:mac_body.mpf", t=""), tmp_path / "s.toml")
    assert (tmp_path / "mac_head.ssh").resolve() in s.source_files()
    with pytest.raises(PisteError, match="texture"):
        loads_scene(text.format(m="builtin:rider", t='texture = "red.ssh"'), tmp_path / "s.toml")
    with pytest.raises(PisteError, match="texture"):
        loads_scene(text.format(m="ssx:mac_body.mpf", t='texture = "nope.ssh"'), tmp_path / "s.toml")
    with pytest.raises(PisteError, match="texture"):
        loads_scene(text.format(m="ssx:mac_body.mpf", t='texture = "hill.npz"'), tmp_path / "s.toml")


def test_render_shows_the_banks_colours(encoded, tmp_path, gl, piste_cache):
    """The same scene with a red and a blue ``suit`` bank: where the two renders differ (the
    rider), the first is red and the second blue."""
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.world.scene_file import load_scene

    y, x = np.mgrid[0:33, 0:33] * 4.0
    np.savez(tmp_path / "hill.npz", z=30.0 - 0.3 * y + 3.0 * np.sin(x / 15.0), dx=np.float64(4.0))
    shutil.copy(encoded / "RIDER.mpf", tmp_path / "RIDER.mpf")
    imgs = {}
    for colour, rgb in (("red", (255, 40, 40)), ("blue", (40, 40, 255))):
        _flat_bank(tmp_path / f"{colour}.ssh", {"suit": rgb})
        (tmp_path / f"{colour}.toml").write_text(SCENE.format(colour=colour))
        b = load_bundle(build_scene(load_scene(tmp_path / f"{colour}.toml")).path)
        assert np.abs(b.rider_model().meshes[0].texture[0, 0, :3].astype(int) - rgb).max() <= 1  # half-bright
        p = ScenePreview(b, size=(96, 72), ctx=gl)
        try:
            imgs[colour] = p.render(camera_at(b, "close", 0, 2), t=0.3).astype(np.float64)
        finally:
            p.release()
    red, blue = imgs["red"], imgs["blue"]
    rider = np.abs(red - blue).max(2) > 20
    assert rider.mean() > 0.01, "the texture bank makes no difference to the picture"
    assert np.mean(red[rider, 0] > red[rider, 2] + 10) > 0.9
    assert np.mean(blue[rider, 2] > blue[rider, 0] + 10) > 0.9
