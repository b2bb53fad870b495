"""SSX Tricky .mpf <-> piste riders: the encoder's limits and report, decoding to a Model, the
file's own palettes as blended-matrix palettes, clips by bone name, glTF export."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from piste.character import BlendedMesh, default_rider, make_lods, palette, skin
from piste.formats.ssx.mpf_encode import model_to_mpf
from piste.formats.ssx.mpf_model import euler_to_matrix, matrix_to_euler, mpf_to_model
from piste.formats.ssx.mpf import DIR_DTYPE, mpf_bytes, parse_mpf, read_mpf, write_mpf


@pytest.fixture(scope="module")
def rider():
    return default_rider(0)


@pytest.fixture(scope="module")
def encoded(rider):
    f, report = model_to_mpf(rider)
    return f, report, mpf_bytes(f)


@pytest.fixture(scope="module")
def decoded(encoded):
    return parse_mpf(encoded[2]).to_model()


def test_to_model_method_is_mpf_to_model(encoded, decoded):
    m = mpf_to_model(parse_mpf(encoded[2]))
    assert m.skeleton.names == decoded.skeleton.names
    assert [lod.n_triangles for lod in m.lods] == [lod.n_triangles for lod in decoded.lods]
    assert np.array_equal(m.meshes[0].positions, decoded.meshes[0].positions)


def test_euler_round_trip():
    e = np.random.default_rng(0).uniform(-1.4, 1.4, (50, 3))
    m = euler_to_matrix(e)
    assert np.allclose(m @ m.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(matrix_to_euler(m), e, atol=1e-9)
    # x first: Rz Ry Rx
    x = euler_to_matrix([0.3, 0, 0])
    assert np.allclose(euler_to_matrix([0.3, 0.2, 0.1]), euler_to_matrix([0, 0, 0.1]) @ euler_to_matrix([0, 0.2, 0]) @ x)


def test_bone_rotation_negates_the_angles():
    """A bone record's (x, y, z) is Rz(-z) Ry(-y) Rx(-x) (SSX-Library, OpenSlope; the retail
    skeleton fits its mesh this way), and the encoder's bone_euler inverts it."""
    from piste.formats.ssx.mpf_model import bone_euler, bone_rotation

    def rx(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    def ry(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    def rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    x, y, z = 0.3, -0.5, 1.1
    assert np.allclose(bone_rotation([x, y, z]), rz(-z) @ ry(-y) @ rx(-x), atol=1e-12)
    assert not np.allclose(bone_rotation([x, y, z]), rz(z) @ ry(y) @ rx(x), atol=1e-3)
    e = np.random.default_rng(1).uniform(-1.4, 1.4, (50, 3))
    assert np.allclose(bone_euler(bone_rotation(e)), e, atol=1e-9)


def test_encoder_obeys_the_game_limits(encoded):
    f, report, b = encoded
    assert f.names == ["Body3000", "Body1500", "Body750", "BodyShdw750"]
    for sub in f.models:
        for p in sub.palettes:
            w = p["weight"].astype(int)
            assert w.sum() == 100 and np.all(w % 25 == 0) and len(p) <= 3
        for lk in sub.links:
            assert 1 <= len(lk.refs) <= 25
            for m in lk.meshes:
                for c in m.chunks:
                    assert c.n_vertices <= 55
                    assert c.slots.min() >= 0 and c.slots.max() < len(lk.refs)
                    assert c.shadow == (sub.name == "BodyShdw750")
                    if not c.shadow:
                        assert np.all(c.uv[:, 3] == 114 + 3 * c.slots)
    assert report["max_chunk_vertices"] <= 55 and report["max_link_matrices"] <= 25
    from piste.formats.ssx.mpf import game_limits

    assert game_limits(f) == []
    types = {g.type for g in f.models[0].groups}
    assert types == {1, 256}  # the face's morph triangles sit in a type-256 group
    assert {g.type for g in f.models[3].groups} == {17} and f.models[3].n_triangles == 770
    e = np.frombuffer(b, DIR_DTYPE, 3, 12)
    assert list(e["counts"][:, 6]) == [3, 3, 3]


def test_report_measures_quantisation(encoded):
    _, r, _ = encoded
    assert r["step"] == 0.25 and r["weights_changed"] > 0
    assert 0 < r["max_weight_error"] <= 0.25 + 1e-6
    assert r["max_bind_error_m"] < 1e-6  # float32 centimetres
    assert 0 < r["max_pose_error_m"] < 0.05  # 25 % steps, mid-"ride"
    assert r["morph_clipped"] == 0 and r["morph_max_error_m"] <= 0.5 / 12.8 * 0.01 + 1e-9
    assert [x["triangles"] for x in r["lods"]] == [3084, 1542, 770]


def test_golden_file_round_trips_byte_identical(encoded, tmp_path):
    f, _, b = encoded
    p = tmp_path / "RIDER.mpf"
    assert write_mpf(f, p) == []
    g = read_mpf(p)
    assert g.unknown == []
    assert write_mpf(g, tmp_path / "copy.mpf") == []
    assert (tmp_path / "copy.mpf").read_bytes() == b
    for s in g.models:
        s.source = None
    assert mpf_bytes(g) == b


def test_decoded_skeleton_matches(rider, decoded):
    sk, want = decoded.skeleton, rider.skeleton
    assert sk.names == want.names and np.array_equal(sk.parents, want.parents)
    assert np.allclose(sk.rest_translation, want.rest_translation, atol=1e-6)
    assert np.allclose(sk.inverse_bind, want.inverse_bind, atol=1e-6)


def test_decoded_lods_have_the_same_triangles(rider, decoded):
    lods = make_lods(rider.meshes[0], steps=0.25, max_bones=3)
    assert [lod.name for lod in decoded.lods] == ["high", "medium", "low"]
    for a, b in zip(lods, decoded.lods):
        assert a.n_triangles == b.n_triangles
        pa, pb = a.mesh.positions[a.mesh.indices], b.mesh.positions[b.mesh.indices]
        d, j = cKDTree(pa.mean(1)).query(pb.mean(1))
        assert d.max() < 1e-5
        na = np.cross(pa[:, 1] - pa[:, 0], pa[:, 2] - pa[:, 0])[j]
        nb = np.cross(pb[:, 1] - pb[:, 0], pb[:, 2] - pb[:, 0])
        assert np.all(np.einsum("ij,ij->i", na, nb) > 0)  # winding kept through strips and chunks
        assert b.mesh.n_vertices <= a.mesh.n_vertices + 8  # welded back (non-indexed strips stored)


def test_file_palettes_are_the_blended_palettes(rider, decoded):
    """The decoded LODs carry the file's palettes; piste's palette() of the same weights agrees
    vertex by vertex, and skinning with the file's palette equals the 'blended' scheme."""
    sk = decoded.skeleton
    pose = rider.clips["grab"].sample(0.4, skeleton=sk)
    m = sk.skin_matrices(pose)
    for lod in decoded.lods:
        mine = palette(lod.mesh, step=0.25, max_bones=3)
        assert mine.size == lod.palette.size
        fb, fw = lod.palette.vertex_weights()
        pb, pw = mine.vertex_weights()
        v = lod.mesh.n_vertices
        dense = lambda b, w: np.add.at(z := np.zeros((v, sk.n_bones)), (np.repeat(np.arange(v), b.shape[1]),  # noqa: E731
                                                                         b.reshape(-1)), w.reshape(-1)) or z
        assert np.allclose(dense(fb, fw), dense(pb, pw))
        assert np.all(np.isin(np.round(fw * 100), [0, 25, 50, 75, 100]))
        got, _ = BlendedMesh(lod.palette, lod.mesh.positions, lod.mesh.normals).apply(m)
        want, _ = skin(lod.mesh, m, scheme="blended", step=0.25, max_bones=3)
        assert np.abs(got - want).max() < 1e-5


def test_clips_by_bone_name_drive_the_decoded_rider(rider, decoded):
    for name in ("ride", "spin"):
        clip = rider.clips[name]
        a = clip.sample(0.3, skeleton=rider.skeleton)
        b = clip.sample(0.3, skeleton=decoded.skeleton)
        wa, wb = rider.skeleton.world_matrices(a), decoded.skeleton.world_matrices(b)
        assert np.abs(wa - wb).max() < 1e-5
    # the posed decoded body follows the posed original (exact skinning, weights in 25 % steps)
    pose = rider.clips["crouch"].sample(0.5, skeleton=decoded.skeleton)
    p_dec, _ = skin(decoded.meshes[0], decoded.skeleton.skin_matrices(pose))
    p_src, _ = skin(rider.meshes[0], rider.skeleton.skin_matrices(rider.clips["crouch"].sample(0.5)))
    d, _ = cKDTree(p_src).query(p_dec)
    assert d.max() < 0.05


def test_morph_targets_decoded(rider, decoded):
    src = rider.meshes[0]
    mesh = decoded.meshes[0]
    assert mesh.n_morphs == 3
    _, j = cKDTree(src.positions).query(mesh.positions)
    err = np.abs(mesh.morph_positions - src.morph_positions[:, j]).max()
    assert err <= 0.5 / 12.8 * 0.01 + 1e-6
    assert np.abs(mesh.morph_positions).max() > 0.005  # the face really moves


def test_decoded_rider_exports_to_gltf(decoded, rider, tmp_path):
    from piste.formats.gltf import load_gltf
    from piste.formats.gltf_export import CharacterExport, export_gltf

    decoded.clips = {"ride": rider.clips["ride"]}
    try:
        export_gltf(tmp_path / "rider.glb", characters=[CharacterExport(decoded, name="mpf")])
    finally:
        decoded.clips = {}
    back = load_gltf(tmp_path / "rider.glb")
    assert back.skeleton is not None and back.n_triangles == decoded.meshes[0].n_triangles
    assert "ride" in back.clips or any("ride" in k for k in back.clips)


def _head_file(body_sub):
    """A head file (file id 2): one bone 'hat' parented across files onto the body's 'head', and
    a small strip weighted 50/50 head/hat and 100 % hat."""
    from piste.formats.ssx.mpf import BONE_DTYPE, PALETTE_ENTRY_DTYPE, Group, Link, Mesh, MpfFile, SubModel, pack_chunks

    head = body_sub.bone_names.index("head")
    bones = np.zeros(1, BONE_DTYPE)
    bones[0] = (b"hat", 0, head, 2, 0, (0.0, 0.0, 15.0), (0.0, 0.0, 0.0), (0, 0, 0), (1, -1, -1, 1, -1, 1))
    pals = [np.array([(50, head, 0), (50, 0, 2)], PALETTE_ENTRY_DTYPE), np.array([(100, 0, 2)], PALETTE_ENTRY_DTYPE)]
    n = 6
    pos = np.array([[x, y, 185.0] for x in (-5.0, 5.0) for y in (-5.0, 0.0, 5.0)], "<f4")
    slot = np.array([0, 0, 0, 1, 1, 1])
    uv = np.zeros((n, 4), "<i2")
    uv[:, 2], uv[:, 3] = 14 + 4 * slot, 114 + 3 * slot
    nrm = np.tile(np.array([0, 0, 32767], "<i2"), (n, 1))
    chunks = pack_chunks([np.array([0, 3, 1, 4, 2, 5])], uv, nrm, pos)
    sub = SubModel(name="Head3000", file_id=2, bones=bones, palettes=pals,
                   groups=[Group(1, 0, [Link([Mesh(chunks)], np.array([0, 1], "<u4"))])])
    return MpfFile([sub])


def test_head_file_parents_across_files(encoded, tmp_path):
    from piste.formats.ssx.mpf import write_mpf
    from piste.pipeline.ssx_rider import load_mpf_rider

    body = parse_mpf(encoded[2])
    head = parse_mpf(mpf_bytes(_head_file(body.models[0])))
    m = mpf_to_model(body, head)
    sk = m.skeleton
    hat, hd = sk.bone_index("hat"), sk.bone_index("head")
    assert sk.parents[hat] == hd and sk.n_bones == 26
    w = sk.bind_pose_world()
    assert np.allclose(w[hat][:3, 3] - w[hd][:3, 3], [0.0, 0.15, 0.0], atol=1e-6)  # SSX +Z 15 cm = piste +Y
    hm = next(x for x in m.meshes if x.name == "Head3000")
    rows = {tuple(sorted((int(j), round(float(x), 2)) for j, x in zip(jj, ww) if x > 0))
            for jj, ww in zip(hm.joints, hm.weights)}
    assert rows == {((hd, 0.5), (hat, 0.5)), ((hat, 1.0),)}
    assert np.allclose(sorted(hm.positions[:, 1]), [1.85] * 6, atol=1e-6)  # SSX z 185 cm = piste y 1.85 m
    with pytest.raises(Exception, match="file id 0"):
        mpf_to_model(head)  # the head alone names body bones
    write_mpf(body, tmp_path / "mac_body.mpf")
    write_mpf(head, tmp_path / "mac_head.mpf")
    r = load_mpf_rider(tmp_path / "mac_body.mpf")
    assert "hat" in r.skeleton.names and set(r.clips) == {"ride", "crouch", "grab", "spin"}


def test_encode_a_gltf_rider(gltf_model):
    src = gltf_model("CesiumMan")
    f, r = model_to_mpf(src, ratios=(1.0, 0.5), names=("Body3000", "Body1500"))
    assert r["max_chunk_vertices"] <= 55 and r["max_link_matrices"] <= 25
    assert r["max_bind_error_m"] < 1e-5 and r["bone_scale_dropped"] < 1e-4
    assert 0 < r["max_pose_error_m"] < 0.1 * src.size()
    m = mpf_to_model(parse_mpf(mpf_bytes(f)))
    assert m.skeleton.names == src.skeleton.names and m.lods[0].n_triangles == src.n_triangles
    fox = gltf_model("Fox")
    f, r = model_to_mpf(fox, ratios=(1.0,), names=("Body3000",))
    assert r["renamed_bones"] and all(len(v) <= 16 for v in r["renamed_bones"].values())
    names = mpf_to_model(parse_mpf(mpf_bytes(f))).skeleton.names
    assert len(set(names)) == fox.skeleton.n_bones and all(len(n) <= 16 for n in names)


def test_schemes_batches_strips_on_the_decoded_rider(rider, decoded):
    """What piste does to a glTF rider works on the decoded one: the three skinning schemes agree
    as they should, PS2 batches from the file's palette pass check_batches, strips round-trip."""
    from piste.character import batch_mesh, check_batches, stripify, unstripify
    from piste.character.strips import canonical_triangles

    sk = decoded.skeleton
    m = sk.skin_matrices(rider.clips["grab"].sample(0.7, skeleton=sk))
    mesh = decoded.meshes[0]
    exact, _ = skin(mesh, m, scheme="exact")
    post, _ = skin(mesh, m, scheme="post_transform", inverse_bind=sk.inverse_bind)
    blended, _ = skin(mesh, m, scheme="blended", step=0.25, max_bones=3)
    assert np.abs(post - exact).max() < 1e-4
    assert np.abs(blended - exact).max() < 1e-4  # the file's weights are already in 25 % steps
    for lod in decoded.lods:
        batches = batch_mesh(lod.mesh, "ps2", palette=lod.palette)
        check_batches(batches, lod.mesh.indices, lod.palette.index, "ps2")
        s = stripify(lod.mesh.indices)
        assert np.array_equal(canonical_triangles(unstripify(s)), canonical_triangles(lod.mesh.indices))


def test_weld_groups_bit_identical_rows():
    from piste.formats.ssx.mpf_model import _weld

    rng = np.random.default_rng(3)
    rows = rng.normal(size=(50, 7)).astype(np.float32)
    key = rows[rng.integers(0, 50, 400)]
    key[0, 0] = -0.0 if key[0, 0] == 0 else key[0, 0]
    first, inv = _weld(key)
    assert np.array_equal(key[first][inv], key)
    assert len(first) == len(np.unique(key, axis=0))


def test_rigid_chunks_call_the_retail_rigid_program(encoded):
    """Render chunks whose vertices each follow one bone call MSCAL 10 in their trailer (as every
    such retail chunk does), the others MSCAL 0; read back from the bytes."""
    from piste.formats.ssx.mpf import mpf_bytes, parse_mpf

    f = parse_mpf(mpf_bytes(encoded[0]))
    seen = set()
    for s in f.models:
        for g in s.groups:
            if g.type != 1:
                continue
            for lk in g.links:
                for m in lk.meshes:
                    for c in m.chunks:
                        single = all(len(s.palettes[int(lk.refs[k])]) == 1 for k in np.unique(c.slots))
                        assert c.program == (10 if single else 0)
                        seen.add(c.program)
    assert seen == {0, 10}


def test_a_rider_file_without_bones_is_refused_by_name(encoded, tmp_path, monkeypatch):
    """An ``.mpf`` whose sub-models hold no bones gives a ConfigError naming the file, not a raw
    AttributeError further on (mypy found the path: ``stand_on_origin`` and the clips read the skeleton)."""
    import dataclasses

    from piste.errors import ConfigError
    from piste.formats.ssx.mpf import write_mpf
    from piste.pipeline import ssx_rider

    write_mpf(parse_mpf(encoded[2]), tmp_path / "boneless.mpf")
    real = ssx_rider.mpf_to_model
    monkeypatch.setattr(ssx_rider, "mpf_to_model", lambda *f, **k: dataclasses.replace(real(*f, **k), skeleton=None))
    with pytest.raises(ConfigError, match="boneless.mpf: no sub-model holds bones"):
        ssx_rider.load_mpf_rider(tmp_path / "boneless.mpf")
