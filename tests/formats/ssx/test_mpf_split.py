"""The game's body/head split: ``piste mpf encode --split-head`` writes ``_body.mpf`` + ``_head.mpf``
(head bones in file id 2, parented onto body bones by file id), both round-trip through the reader,
decode to the same posed rider as one file, and the build cache tracks the head partner."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from piste.character import default_rider, skin
from piste.cli import main
from piste.formats.ssx.mpf import read_mpf, write_mpf
from piste.formats.ssx.mpf_encode import HEAD_FILE_ID, model_to_mpf, model_to_mpf_pair
from piste.formats.ssx.mpf_model import mpf_to_model
from piste.pipeline.ssx_rider import load_mpf_rider


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("split")
    assert main(["mpf", "encode", str(d / "mac.mpf"), "--split-head", "--no-texture",
                 "--report", str(d / "r.json")]) == 0
    return d


def test_cli_writes_the_pair(pair, capsys):
    assert (pair / "mac_body.mpf").is_file() and (pair / "mac_head.mpf").is_file()
    assert not (pair / "mac.mpf").exists()
    body, head = read_mpf(pair / "mac_body.mpf"), read_mpf(pair / "mac_head.mpf")
    assert body.names == ["Body3000", "Body1500", "Body750", "BodyShdw750"]
    assert head.names == ["Head3000", "Head1500", "Head750"]
    assert {s.file_id for s in body.models} == {0} and {s.file_id for s in head.models} == {HEAD_FILE_ID}
    rep = json.loads((pair / "r.json").read_text())["split"]
    assert rep["head_bones"] == ["head", "jaw"]
    assert [x["head"] + x["body"] for x in rep["lods"]] == [3084, 1542, 770] and all(x["head"] > 0 for x in rep["lods"])
    for name in ("mac_body", "mac_head"):  # unedited files round-trip byte-identical
        assert main(["mpf", "copy", str(pair / f"{name}.mpf"), str(pair / f"{name}_copy.mpf")]) == 0
        assert (pair / f"{name}_copy.mpf").read_bytes() == (pair / f"{name}.mpf").read_bytes()
    capsys.readouterr()
    assert main(["mpf", "info", str(pair / "mac_head.mpf"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["game_limits"] == [] and info["unknown"] == []


def test_head_bones_reference_the_body_by_file_id(pair):
    body, head = read_mpf(pair / "mac_body.mpf"), read_mpf(pair / "mac_head.mpf")
    bnames = body.models[0].bone_names
    hb = head.models[0].bones
    assert [n.decode() for n in hb["name"]] == ["head", "jaw"] and "head" not in bnames
    assert (int(hb["parent_file"][0]), int(hb["parent_bone"][0])) == (0, bnames.index("neck"))
    assert (int(hb["parent_file"][1]), int(hb["parent_bone"][1])) == (HEAD_FILE_ID, 0)
    files = {int(e["file"]) for p in head.models[0].palettes for e in p}
    assert files == {0, HEAD_FILE_ID}  # neck vertices blend body and head bones across the files
    with pytest.raises(Exception, match="file id"):
        mpf_to_model(head)  # the head alone names body bones


def test_pair_decodes_to_the_same_posed_rider(pair):
    rider = default_rider(0)
    one = mpf_to_model(model_to_mpf(rider)[0])
    two = load_mpf_rider(pair / "mac_body.mpf")  # reads mac_head.mpf beside it
    assert sorted(two.skeleton.names) == sorted(one.skeleton.names)
    assert [m.name for m in two.meshes] == ["Body3000", "Head3000"]
    assert [lod.n_triangles for lod in two.lods] == [lod.n_triangles for lod in one.lods]
    w1, w2 = one.skeleton.bind_pose_world(), two.skeleton.bind_pose_world()
    for n in one.skeleton.names:
        assert np.abs(w1[one.skeleton.get(n)] - w2[two.skeleton.get(n)]).max() < 1e-6
    for clip, t in (("grab", 0.6), ("spin", 0.3)):
        for k in range(3):  # every LOD: the head file's lower LODs name the right bones too
            p1, _ = skin(one.lods[k].mesh, one.skeleton.skin_matrices(rider.clips[clip].sample(t, skeleton=one.skeleton)))
            p2, _ = skin(two.lods[k].mesh, two.skeleton.skin_matrices(two.clips[clip].sample(t, skeleton=two.skeleton)))
            assert cKDTree(p1).query(p2)[0].max() < 1e-5 and cKDTree(p2).query(p1)[0].max() < 1e-5, (clip, k)


def test_shadow_sub_model_skins_like_the_last_lod():
    """The shadow sub-model's weight palettes are the last LOD's (a variable clash once gave it
    the posed vertex positions as bone references: garbage palettes, or an OverflowError on Fox)."""
    f, _ = model_to_mpf(default_rider(0))
    last, shadow = f["Body750"], f["BodyShdw750"]
    assert [p.tolist() for p in shadow.palettes] == [p.tolist() for p in last.palettes]


def test_split_refuses_a_bad_head_bone():
    from piste.errors import ConfigError

    with pytest.raises(ConfigError, match="no head bone 'hat'"):
        model_to_mpf_pair(default_rider(0), head_bone="hat")
    with pytest.raises(ConfigError, match="root"):
        model_to_mpf_pair(default_rider(0), head_bone="root")


def test_split_of_a_model_without_a_skeleton_is_a_clear_error():
    """Was an AttributeError on None (found by mypy); now the ConfigError model_to_mpf gives."""
    from dataclasses import replace

    from piste.errors import ConfigError

    with pytest.raises(ConfigError, match="no skeleton"):
        model_to_mpf_pair(replace(default_rider(0), skeleton=None))


def test_build_cache_tracks_the_head_partner(pair, tmp_path, piste_cache):
    import shutil

    from piste.pipeline.build import build_scene
    from piste.world.scene_file import load_scene

    for n in ("mac_body.mpf", "mac_head.mpf"):
        shutil.copy(pair / n, tmp_path / n)
    y, x = np.mgrid[0:17, 0:17] * 4.0
    np.savez(tmp_path / "hill.npz", z=20.0 - 0.3 * y + np.sin(x / 9.0), dx=np.float64(4.0))
    (tmp_path / "s.toml").write_text('[terrain]\nsource = "hill.npz"\n\n[lightmap]\nres = 4\n\n[visibility]\n'
                                     'cell = 32.0\n\n[[riders]]\nmodel = "ssx:mac_body.mpf"\nposition = [30.0, 30.0]\n')
    scene = load_scene(tmp_path / "s.toml")
    assert (tmp_path / "mac_head.mpf").resolve() in scene.source_files()
    assert not build_scene(scene).steps["characters"]["cached"]
    assert build_scene(load_scene(tmp_path / "s.toml")).steps["characters"]["cached"]
    head = read_mpf(tmp_path / "mac_head.mpf")
    head.models[0].bones["translation"][1] += 1.0  # move the jaw 1 cm
    write_mpf(head, tmp_path / "mac_head.mpf")
    assert not build_scene(load_scene(tmp_path / "s.toml")).steps["characters"]["cached"]


def test_split_rider_keeps_its_face_morphs_and_texture(tmp_path):
    """The LOD meshes (what the character build step takes) carry both files' morph targets, and
    the texture bank written beside the body textures the head's material too."""
    assert main(["mpf", "encode", str(tmp_path / "eddie_body.mpf"), "--split-head", "--ratios", "1", "0.5"]) == 0
    assert (tmp_path / "eddie_body.ssh").is_file() and (tmp_path / "eddie_head.mpf").is_file()
    r = load_mpf_rider(tmp_path / "eddie_body.mpf")
    assert r.materials == [("suit", 0)] and r.meshes[0].texture is not None
    lod = r.lods[0].mesh
    assert {n.split(".")[0] for n in lod.morph_names} == {"Body3000", "Head3000"}
    moved = np.abs(lod.morph_positions).max(axis=(0, 2)) > 0
    head_bones = [r.skeleton.get("head"), r.skeleton.get("jaw")]
    assert moved.any() and np.isin(lod.joints[moved], head_bones).any()
