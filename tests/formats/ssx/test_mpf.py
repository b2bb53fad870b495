"""SSX Tricky .mpf: layout, byte-identical round trips, in-place patching, unknown bytes kept."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import FormatError, ValidationError
from piste.formats.ssx.mpf import (
    BONE_DTYPE, DIR_DTYPE, PALETTE_ENTRY_DTYPE, Group, Link, Mesh, MorphKey, MpfFile, SubModel, mpf_bytes,
    pack_chunks, parse_mpf, read_mpf, strip_triangles, write_mpf,
)


def small_mpf(seed=0, n=130, shadow=True) -> MpfFile:
    """A hand-built file: 3 bones, 3 palettes, a render group, a morph group, a shadow group."""
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(n, 3)).astype("<f4") * 50
    uv = np.zeros((n, 4), "<i2")
    uv[:, :2] = rng.integers(0, 4096, (n, 2))
    slot = rng.integers(0, 3, n)
    uv[:, 2], uv[:, 3] = 14 + 4 * slot, 114 + 3 * slot
    nrm = rng.integers(-32767, 32767, (n, 3)).astype("<i2")
    strips = [np.arange(0, 70), np.arange(70, 75), np.arange(75, n)]
    chunks = pack_chunks(strips, uv, nrm, pos)
    pal = [np.array([(100, 0, 0)], PALETTE_ENTRY_DTYPE), np.array([(50, 0, 0), (50, 1, 0)], PALETTE_ENTRY_DTYPE),
           np.array([(25, 0, 0), (50, 1, 0), (25, 2, 0)], PALETTE_ENTRY_DTYPE)]
    bones = np.zeros(3, BONE_DTYPE)
    bones["name"] = [b"hips", b"spine", b"head"]
    bones["parent_file"] = [-1, 0, 0]
    bones["parent_bone"] = [-1, 0, 1]
    bones["translation"] = [[0, 0, 100], [0, 0, 20], [0, 0, 40]]
    keys = [MorphKey(deltas=rng.integers(-100, 100, (chunks[0].n_vertices, 3)).astype("i1")) for _ in range(2)]
    groups = [Group(1, 0, [Link([Mesh(chunks[1:])], np.array([0, 1, 2], "<u4"))]),
              Group(256, 0, [Link([Mesh(chunks[:1], morphs=keys)], np.array([0, 1, 2], "<u4"))])]
    if shadow:
        sh = pack_chunks([np.arange(20)], None, None, pos, shadow_slots=np.full(n, 14, "<u4"))
        groups.append(Group(17, 0, [Link([Mesh(sh)], np.array([1], "<u4"))]))
    body = SubModel(name="Body3000", bones=bones, palettes=pal, morph_keys=2, groups=groups)
    uv1 = uv.copy()
    uv1[:, 2], uv1[:, 3] = 14 + 4 * (slot % 2), 114 + 3 * (slot % 2)
    other = SubModel(name="Body750", bones=bones.copy(), palettes=pal[:2], groups=[
        Group(1, 0, [Link([Mesh(pack_chunks([np.arange(10)], uv1, nrm, pos))], np.array([0, 1], "<u4"))])])
    return MpfFile([body, other])


def test_layout_facts():
    b = mpf_bytes(small_mpf())
    assert int(np.frombuffer(b, "<u4", 1, 0)[0]) == 8
    count, dir_off = np.frombuffer(b, "<i2", 2, 4)
    assert (count, dir_off) == (2, 12)
    assert int(np.frombuffer(b, "<u4", 1, 8)[0]) == 12 + 80 * 2 + 4
    e = np.frombuffer(b, DIR_DTYPE, 2, 12)
    assert bytes(e[0]["name"]).rstrip(b"\0") == b"Body3000"
    assert list(e[0]["counts"]) == [3, 3, 3, 3, 0, 0, 2]  # palettes, wrefs, groups, bones, materials, ik, morphs
    assert int(e[0]["sections"][4]) == 0  # materials first
    base = 176 + int(e[0]["offset"])
    # palette header: count, offset, constant 36; first entry 100 % on bone 0 of file 0
    ph = np.frombuffer(b, "<u4", 3, base + int(e[0]["sections"][6]))
    assert ph[0] == 1 and ph[2] == 36
    assert tuple(np.frombuffer(b, PALETTE_ENTRY_DTYPE, 1, base + int(ph[1]))[0]) == (100, 0, 0)
    # first chunk: 24-bit qword count, byte 31 = 0x6C, strip-table header (strips, 14, 114, vertices)
    f = parse_mpf(b)
    c = f.models[0].groups[0].links[0].meshes[0].chunks[0]
    o = base + c.offset
    assert b[o + 31] == 0x6C
    strips, w14, w114, nv = np.frombuffer(b, "<u4", 4, o + 48)
    assert (w14, w114) == (14, 114) and nv == c.n_vertices <= 55
    qwc = int.from_bytes(b[o:o + 3], "little")
    assert qwc == (64 + 16 * strips) // 16 - 1
    # the retail layout: GIF tag 0x412 (ST, RGBAQ, XYZ2), PRIM 0x5C, 3 registers
    gif = np.frombuffer(b, "<u8", 2, o + 32)
    assert int(gif[1]) == 0x412 and (int(gif[0]) >> 47) & 0x7FF == 0x5C and int(gif[0]) >> 60 == 3
    assert int(gif[0]) & 0x7FFF == c.n_vertices
    # after the strips a DMA CNT quadword whose qwc covers the UV, normal and position sections
    q = o + 64 + 16 * int(strips)
    tag = int(np.frombuffer(b, "<u4", 1, q)[0])
    v = c.n_vertices
    sections = 3 * 3 + (-(-8 * v // 16)) + (-(-6 * v // 16)) + (-(-12 * v // 16))
    assert tag >> 28 == 1 and tag & 0xFFFF == sections
    assert np.frombuffer(b, "<u4", 4, q + 16).tolist() == [0, 0x30000000, 0, 0]  # NOP, STROW, row
    assert np.frombuffer(b, "<u4", 4, q + 32).tolist() == [0x1000, 0x1000, 0x20000000, 0x50505050]
    assert np.frombuffer(b, "<i2", 4 * v, q + 64).reshape(v, 4).tolist() == c.uv.tolist()
    # shadow chunks: PRIM 0x44 with one register (XYZ2)
    sc = f.models[0].groups[2].links[0].meshes[0].chunks[0]
    gif = np.frombuffer(b, "<u8", 2, base + sc.offset + 32)
    assert int(gif[1]) == 0x4 and (int(gif[0]) >> 47) & 0x7FF == 0x44 and int(gif[0]) >> 60 == 1
    # each group's last mesh ends with the end packets A (32 bytes) and B (48 bytes)
    m = f.models[0].groups[0].links[0].meshes[-1]
    assert m.end is not None and len(m.end) == 80
    assert np.frombuffer(m.end, "<u4").tolist() == [0x60000001, 0, 0, 0, 0, 0x01000101, 0, 0, 0x60000001, 0, 0, 0,
                                                    0, 0, 0, 0x01000101, 0, 0x10000000, 0, 0x14000000]


def test_old_layout_without_the_cnt_quadword_is_refused_clearly():
    f = small_mpf()
    b = bytearray(mpf_bytes(f))
    g = parse_mpf(bytes(b))
    c = g.models[0].groups[0].links[0].meshes[0].chunks[0]
    base = 176 + int(np.frombuffer(bytes(b), DIR_DTYPE, 1, 12)[0]["offset"])
    q = base + c.offset + 64 + 16 * len(c.strip_lengths)
    b[q:q + 4] = (0x10000000 | 2).to_bytes(4, "little")  # a section's own tag, as piste wrote before
    with pytest.raises(FormatError, match="DMA CNT quadword") as e:
        parse_mpf(bytes(b), "old.mpf")
    assert e.value.field.endswith("dma_cnt") and "old.mpf" in str(e.value)


def test_round_trip_byte_identical_and_rebuild(tmp_path):
    f = small_mpf()
    b = mpf_bytes(f)
    p = tmp_path / "rider.mpf"
    assert write_mpf(f, p) == []
    g = read_mpf(p)
    assert g.unknown == []
    out = tmp_path / "again.mpf"
    assert write_mpf(g, out) == []
    assert out.read_bytes() == b
    for s in g.models:  # forget the source: the canonical layout reproduces the same bytes
        s.source = None
    g.source = None
    assert mpf_bytes(g) == b


def test_values_survive():
    f = small_mpf()
    g = parse_mpf(mpf_bytes(f))
    for a, b in zip(f.models, g.models):
        assert a.bone_names == b.bone_names
        assert np.array_equal(a.bones, b.bones)
        assert [p.tolist() for p in a.palettes] == [p.tolist() for p in b.palettes]
        for la, lb in zip(a.links, b.links):
            assert np.array_equal(la.refs, lb.refs)
            for ma, mb in zip(la.meshes, lb.meshes):
                assert [k.deltas.tolist() for k in ma.morphs] == [k.deltas.tolist() for k in mb.morphs]
                for ca, cb in zip(ma.chunks, mb.chunks):
                    assert np.array_equal(ca.positions, cb.positions)
                    assert np.array_equal(ca.strip_lengths, cb.strip_lengths)
                    if ca.uv is None:
                        assert cb.uv is None and np.array_equal(ca.shadow_slots, cb.shadow_slots)
                    else:
                        assert np.array_equal(ca.uv, cb.uv) and np.array_equal(ca.normals, cb.normals)
    assert g.models[0].groups[2].type == 17 and g.models[0].groups[2].links[0].meshes[0].chunks[0].shadow


def test_edit_values_patches_in_place_and_keeps_unknown_bytes():
    b = bytearray(mpf_bytes(small_mpf()))
    b += b"MODDER-NOTE-1234"  # bytes after the last blob: not understood, must be kept
    f = parse_mpf(bytes(b))
    assert any(w == "file" and n == 16 for w, o, n, _ in f.unknown)
    assert mpf_bytes(f) == bytes(b)
    c = f.models[0].groups[0].links[0].meshes[0].chunks[1]
    c.positions[3] = (1.5, -2.0, 3.25)
    f.models[0].bones["translation"][1] = (0, 1, 22)
    f.models[0].palettes[1]["weight"] = (75, 25)
    f.models[0].groups[1].links[0].meshes[0].morphs[1].deltas[0] = (1, 2, 3)
    out = mpf_bytes(f)
    assert len(out) == len(b) and out.endswith(b"MODDER-NOTE-1234")
    g = parse_mpf(out)
    assert np.array_equal(g.models[0].groups[0].links[0].meshes[0].chunks[1].positions[3], [1.5, -2.0, 3.25])
    assert np.allclose(g.models[0].bones["translation"][1], (0, 1, 22))
    assert g.models[0].palettes[1]["weight"].tolist() == [75, 25]
    assert g.models[0].groups[1].links[0].meshes[0].morphs[1].deltas[0].tolist() == [1, 2, 3]


def test_shape_change_is_laid_out_anew_with_a_note(tmp_path):
    f = parse_mpf(mpf_bytes(small_mpf()))
    f.models[1].bones = f.models[1].bones[:2]
    notes = write_mpf(f, tmp_path / "x.mpf")
    assert notes and "laid out anew" in notes[0]
    g = read_mpf(tmp_path / "x.mpf")
    assert len(g.models[1].bones) == 2 and g.models[0].n_vertices == f.models[0].n_vertices


def test_gap_inside_a_blob_is_reported_and_kept():
    f = small_mpf()
    b = bytearray(mpf_bytes(f))
    g = parse_mpf(bytes(b))
    # the padding between the last mesh header and the 16-aligned mesh data is a gap of zero bytes
    e = np.frombuffer(bytes(b), DIR_DTYPE, 2, 12)
    base = 176 + int(e[0]["offset"])
    mesh_data = int(e[0]["sections"][3])
    last = max(m.offset for lk in g.models[0].links for m in lk.meshes) + 12
    assert 2 <= mesh_data - last < 16 and not any(b[base + last:base + mesh_data])
    b[base + last:base + last + 2] = b"\xab\xcd"
    h = parse_mpf(bytes(b))
    assert any(w == "Body3000 blob" and o == last for w, o, *_ in h.unknown)
    assert mpf_bytes(h) == bytes(b)


def test_strip_triangles_keep_winding():
    t = strip_triangles([4, 3])
    assert t.tolist() == [[0, 1, 2], [2, 1, 3], [4, 5, 6]]
    assert strip_triangles([2, 1]).shape == (0, 3)


def test_pack_chunks_limit_and_winding():
    n = 200
    pos = np.random.default_rng(1).normal(size=(n, 3)).astype("<f4")
    uv = np.zeros((n, 4), "<i2")
    uv[:, 2], uv[:, 3] = 14, 114
    nrm = np.zeros((n, 3), "<i2")
    chunks = pack_chunks([np.arange(n)], uv, nrm, pos)
    assert all(c.n_vertices <= 55 for c in chunks)  # the encoder's packing (retail allows 59)
    got = {tuple(np.round(pos_t, 5).ravel()) for c in chunks for pos_t in c.positions[c.triangles()]}
    s = np.arange(n)
    want = {tuple(np.round(pos[t], 5).ravel()) for t in strip_triangles([n])}
    assert got == want and len(want) == n - 2
    with pytest.raises(ValidationError):
        pack_chunks([s], uv, nrm, pos, max_vertices=3)


def test_not_a_model_file():
    with pytest.raises(FormatError, match="music"):
        parse_mpf(b"xDFP" + bytes(20), "song.mpf")


def test_game_limits():
    from piste.formats.ssx.mpf import game_limits

    f = small_mpf()
    assert game_limits(f) == []
    f.models[0].palettes[1]["weight"] = (40, 60)
    f.models[0].links[0].refs = np.arange(30, dtype="<u4") % 3
    f.models[1].name = "Body3000"[:7] + "0"  # "Body3000" again, shortened: still unique at 15
    c = f.models[0].links[0].meshes[0].chunks[0]
    c.strip_lengths = np.array([60], "<u4")
    c.positions = np.zeros((60, 3), "<f4")
    sc = f.models[0].groups[2].links[0].meshes[0].chunks[0]
    sc.strip_lengths = np.array([166], "<u4")
    sc.positions = np.zeros((166, 3), "<f4")
    problems = [p for _, p in game_limits(f)]
    assert any("40, 60" in p for p in problems) and any("30 palettes" in p for p in problems)
    assert any("chunk of 60 vertices" in p and "at most 59" in p for p in problems)
    assert any("shadow chunk of 166 vertices" in p and "at most 165" in p for p in problems)
    h = small_mpf()  # 59 and 165 are retail sizes: allowed
    h.models[0].links[0].meshes[0].chunks[0].strip_lengths = np.array([59], "<u4")
    h.models[0].links[0].meshes[0].chunks[0].positions = np.zeros((59, 3), "<f4")
    assert game_limits(h) == []
    g = small_mpf()
    g.models[0].name, g.models[1].name = "ZZZZZZZZZZZZZZZA", "ZZZZZZZZZZZZZZZB"
    assert any("15 characters" in p for _, p in game_limits(g))


def test_tag_differences_name_chunks_with_foreign_tags():
    from piste.formats.ssx.mpf import tag_differences

    b = bytearray(mpf_bytes(small_mpf()))
    f = parse_mpf(bytes(b))
    assert tag_differences(f) == []
    c = f.models[0].groups[0].links[0].meshes[0].chunks[0]
    base = 176 + int(np.frombuffer(bytes(b), DIR_DTYPE, 1, 12)[0]["offset"])
    b[base + c.offset + 8:base + c.offset + 12] = b"\x01\x02\x03\x04"  # a VIF code piste would not write
    g = parse_mpf(bytes(b))
    assert tag_differences(g) == [("Body3000", 1, len([x for lk in g.models[0].links for m in lk.meshes
                                                         for x in m.chunks]), 4)]
    assert mpf_bytes(g) == bytes(b)  # kept
