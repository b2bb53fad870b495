"""Retail-style bone names (``hips``, ``l_clav``, ``l_thigh``, ``r_calf``, ...): piste's shared clips
drive a decoded .mpf rider whose bones are not named like the default rider's, through the
built-in bone map (roles from the names)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from piste.character import default_rider, skin
from piste.character.model import Skeleton
from piste.character.retarget import bone_roles, builtin_bone_map
from piste.formats.ssx.mpf import write_mpf
from piste.formats.ssx.mpf_encode import model_to_mpf
from piste.pipeline.ssx_rider import load_mpf_rider

#: the default rider's names -> SSX-style names (retail riders: ``hips`` root, ``l_clav`` / ``r_clav``,
#: ``l_thigh`` / ``r_thigh``: OpenSlope spec 240; the rest in the same style)
SSX_NAMES = {"pelvis": "hips", "spine1": "spine", "spine2": "spine1", "spine3": "chest"}
for _s in ("l", "r"):
    SSX_NAMES.update({f"clavicle_{_s}": f"{_s}_clav", f"upperarm_{_s}": f"{_s}_uparm", f"lowerarm_{_s}": f"{_s}_forearm",
                      f"hand_{_s}": f"{_s}_hand", f"thigh_{_s}": f"{_s}_thigh", f"shin_{_s}": f"{_s}_calf",
                      f"foot_{_s}": f"{_s}_foot", f"toe_{_s}": f"{_s}_toe"})


def _renamed(model):
    sk = model.skeleton
    names = [SSX_NAMES.get(n, n) for n in sk.names]
    rs = Skeleton(names, sk.parents, sk.rest_translation, sk.rest_rotation, sk.rest_scale, sk.inverse_bind)
    return replace(model, skeleton=rs, clips={})


@pytest.fixture(scope="module")
def riders(tmp_path_factory):
    d = tmp_path_factory.mktemp("retail")
    src = default_rider(0)
    write_mpf(model_to_mpf(src)[0], d / "PLAIN.mpf")
    write_mpf(model_to_mpf(_renamed(src))[0], d / "RETAIL.mpf")
    return load_mpf_rider(d / "PLAIN.mpf"), load_mpf_rider(d / "RETAIL.mpf")


def test_retail_names_get_roles():
    """A 19-bone body in the retail layout (hips; l_clav 5, r_clav 9, l_thigh 13, r_thigh 16)."""
    names = ["hips", "spine", "spine1", "neck", "head", "l_clav", "l_uparm", "l_forearm", "l_hand", "r_clav",
             "r_uparm", "r_forearm", "r_hand", "l_thigh", "l_calf", "l_foot", "r_thigh", "r_calf", "r_foot"]
    parents = [-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 0, 16, 17]
    n = len(names)
    sk = Skeleton(names, np.array(parents), np.tile([0.0, 0.1, 0.0], (n, 1)), np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
                  np.ones((n, 3)), np.tile(np.eye(4), (n, 1, 1)))
    r = bone_roles(sk)
    assert r["hips"] == "pelvis" and r["l_clav"] == "clavicle_l" and r["r_calf"] == "shin_r"
    assert (r["spine"], r["spine1"]) == ("spine1", "spine3")  # a two-bone spine: first and chest
    m = builtin_bone_map(default_rider(0).skeleton, sk)
    assert m["pelvis"] == "hips" and m["thigh_l"] == "l_thigh" and m["lowerarm_r"] == "r_forearm"
    assert m["head"] == "head" and "spine2" not in m  # the rider's middle spine bone has no partner here
    assert len(set(m.values())) == len(m)


def test_same_name_false_friends_are_not_joined():
    """The rider's ``spine1`` is the SSX-named rig's ``spine`` (its ``spine1`` is one bone up)."""
    src = default_rider(0).skeleton
    m = builtin_bone_map(src, _renamed(default_rider(0)).skeleton)
    assert all(SSX_NAMES.get(k, k) == v for k, v in m.items()) and len(m) == src.n_bones


@pytest.mark.parametrize("clip,t", [("ride", 0.3), ("crouch", 0.5), ("grab", 0.7), ("spin", 0.4)])
def test_shared_clips_drive_a_retail_named_rider(riders, clip, t):
    plain, retail = riders
    assert "hips" in retail.skeleton.names and "pelvis" not in retail.skeleton.names
    assert set(retail.clips) == {"ride", "crouch", "grab", "spin"}
    c = retail.clips[clip]
    assert "hips" in c.tracks and "pelvis" not in c.tracks
    sk_p, sk_r = plain.skeleton, retail.skeleton
    got, _ = skin(retail.meshes[0], sk_r.skin_matrices(c.sample(t, skeleton=sk_r)))
    want, _ = skin(plain.meshes[0], sk_p.skin_matrices(plain.clips[clip].sample(t, skeleton=sk_p)))
    bind, _ = skin(retail.meshes[0], sk_r.skin_matrices(None))
    assert np.abs(got - bind).max() > 0.02, f"{clip}: the retail-named rider stays in its bind pose"
    assert np.abs(got - want).max() < 2e-5  # float32 tolerance on metre-sized coordinates


def test_notes_say_the_clips_were_retargeted(riders):
    plain, retail = riders
    assert any("retargeted by the built-in bone map" in n and "pelvis -> hips" in n for n in retail.notes)
    assert not any("retargeted" in n for n in plain.notes)


def test_a_hips_centred_rider_is_stood_on_its_origin(riders, tmp_path):
    """Retail riders are centred on the hips (moby's body reaches 0.98 m below its origin): the
    loaded rider is lifted so its feet are at height 0, and it poses exactly as the same rider
    encoded feet-down."""
    plain = riders[0]
    src = default_rider(0)
    sk = src.skeleton
    h = 0.97
    down = np.array([0.0, -h, 0.0])
    up4 = np.eye(4)
    up4[1, 3] = h
    rest_t = sk.rest_translation.copy()
    rest_t[sk.parents < 0] += down
    hs = Skeleton(sk.names, sk.parents, rest_t, sk.rest_rotation, sk.rest_scale, sk.inverse_bind @ up4)
    meshes = [replace(m, positions=(m.positions + down).astype(np.float32)) for m in src.meshes]
    write_mpf(model_to_mpf(replace(src, skeleton=hs, meshes=meshes, clips={}))[0], tmp_path / "HIPS.mpf")
    m = load_mpf_rider(tmp_path / "HIPS.mpf")
    assert abs(float(m.lods[0].mesh.positions[:, 1].min())) < 1e-4
    assert any("lifted 0.97 m" in n for n in m.notes) and not any("lifted" in n for n in plain.notes)
    for clip, t in (("ride", 0.3), ("grab", 0.7)):
        got, _ = skin(m.meshes[0], m.skeleton.skin_matrices(m.clips[clip].sample(t, skeleton=m.skeleton)))
        want, _ = skin(plain.meshes[0], plain.skeleton.skin_matrices(plain.clips[clip].sample(t, skeleton=plain.skeleton)))
        from scipy.spatial import cKDTree  # the encoder may order the shifted vertices differently

        assert cKDTree(want).query(got)[0].max() < 1e-4 and cKDTree(got).query(want)[0].max() < 1e-4, clip
