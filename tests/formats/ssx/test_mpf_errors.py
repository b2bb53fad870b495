"""Bad .mpf input: FormatError naming the file, the sub-model/chunk and the field; never a numpy
or struct traceback; hypothesis round trips and corruptions (the optional real-file tests are in
test_mpf_real_files.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from piste.errors import FormatError, ValidationError
from piste.formats.ssx.mpf import (
    BONE_DTYPE, DIR_DTYPE, PALETTE_ENTRY_DTYPE, Group, Link, Mesh, MorphKey, MpfFile, SubModel, mpf_bytes,
    pack_chunks, parse_mpf, read_mpf,
)


@pytest.fixture(scope="module")
def golden():
    from piste.character import default_rider
    from piste.formats.ssx.mpf_encode import model_to_mpf

    f, _ = model_to_mpf(default_rider(0), ratios=(1.0, 0.25), names=("Body3000", "Body750"))
    return mpf_bytes(f)


def _blob_base(b: bytes, i: int) -> int:
    start = int(np.frombuffer(b, "<u4", 1, 8)[0])
    return start + int(np.frombuffer(b, DIR_DTYPE, i + 1, 12)[i]["offset"])


def _entry_at(i: int) -> int:
    return 12 + 80 * i


def _fail(data: bytes, match: str, field: str | None = None):
    with pytest.raises(FormatError, match=match) as e:
        parse_mpf(bytes(data), "RIDER.mpf")
    assert "RIDER.mpf" in str(e.value)
    if field is not None:
        assert e.value.field is not None and field in e.value.field, e.value.field
    return e.value


def test_truncated_header():
    _fail(b"\x08\0\0\0\x01", "shorter than the 12-byte", "header")


def test_truncated_file(golden):
    _fail(golden[: len(golden) // 2], "runs past the end", "directory")


def test_bad_format_id(golden):
    b = bytearray(golden)
    b[0] = 13
    _fail(b, "format id 13", "header.format_id")


def test_directory_past_end(golden):
    b = bytearray(golden)
    b[4:6] = np.array([30000], "<i2").tobytes()
    _fail(b, "sub-model count 30000", "header.count")
    b[4:6] = np.array([100], "<i2").tobytes()
    _fail(b[:1000], "directory of 100 entries", "header.directory_offset")
    b[4:6] = np.array([900], "<i2").tobytes()
    _fail(b, r"data start \d+ lies inside the directory of 900 entries", "header.data_start")


def test_bone_count_past_end(golden):
    b = bytearray(golden)
    o = _entry_at(0) + 0x3C + 2 * 3  # counts: palettes, wrefs, groups, bones
    b[o:o + 2] = np.array([30000], "<i2").tobytes()
    e = _fail(b, "Body3000", "bones")
    assert "past the end" in str(e) or "impossible" in str(e)


def test_section_offset_past_end(golden):
    b = bytearray(golden)
    o = _entry_at(1) + 0x18 + 4 * 6  # palettes section offset
    b[o:o + 4] = np.array([0x7FFFFFF0], "<u4").tobytes()
    _fail(b, "Body750.*run past the end", "palettes")


def test_weights_not_summing_to_100(golden):
    f = parse_mpf(golden)
    sub = f.models[0]
    b = bytearray(golden)
    o = _blob_base(golden, 0) + sub._offsets["palettes"][1]
    b[o:o + 2] = np.array([int(sub.palettes[1]["weight"][0]) + 1], "<i2").tobytes()
    _fail(b, "palette 1: weights sum to 101 %", "palette1.weight")


def test_nan_bone(golden):
    e = np.frombuffer(golden, DIR_DTYPE, 1, 12)[0]
    b = bytearray(golden)
    o = _blob_base(golden, 0) + int(e["sections"][0]) + 84 * 3 + 0x18  # bone 3 translation x
    b[o:o + 4] = np.array([np.nan], "<f4").tobytes()
    _fail(b, "bone 3: bind translation or rotation is NaN", "bones.translation")


def test_mesh_headers_repeating_one_stream_are_refused():
    """A hostile file pointing 2,000 mesh headers at one 40-chunk stream: parsed once, then refused
    (80,000 chunk references) instead of decoding the same geometry 2,000 times."""
    from piste.formats.ssx.mpf import BONE_DTYPE, PALETTE_ENTRY_DTYPE, Group, Link, Mesh, MpfFile, SubModel, pack_chunks

    n = 55 * 40
    uv = np.zeros((n, 4), "<i2")
    uv[:, 2], uv[:, 3] = 14, 114
    nrm, pos = np.zeros((n, 3), "<i2"), np.zeros((n, 3), "<f4")
    big = pack_chunks([np.arange(i, i + 55) for i in range(0, n, 55)], uv, nrm, pos)
    small = [Mesh(pack_chunks([np.arange(3)], uv, nrm, pos)) for _ in range(1999)]
    sub = SubModel("Body3000", bones=np.zeros(1, BONE_DTYPE), palettes=[np.array([(100, 0, 0)], PALETTE_ENTRY_DTYPE)],
                   groups=[Group(1, 0, [Link([Mesh(big)] + small, np.array([0], "<u4"))])])
    b = bytearray(mpf_bytes(MpfFile([sub])))
    f = parse_mpf(bytes(b))
    hdr0 = _blob_base(bytes(b), 0) + f.models[0].groups[0].links[0].meshes[0].offset
    for i in range(1, 2000):
        b[hdr0 + 12 * i:hdr0 + 12 * i + 4] = b[hdr0:hdr0 + 4]
    _fail(b, "chunk references", "mesh_offset")


def _first_chunk(golden):
    f = parse_mpf(golden)
    c = f.models[0].groups[0].links[0].meshes[0].chunks[0]
    return f, c, _blob_base(golden, 0) + c.offset


def test_nan_position(golden):
    _, c, o = _first_chunk(golden)
    s = len(c.strip_lengths)
    v = c.n_vertices
    p = o + 64 + 16 * s + 16  # uv section header (after the DMA CNT quadword)
    p = -(-(p + 48 + 8 * v) // 16) * 16 + 48  # normals data
    p = -(-(p + 6 * v) // 16) * 16 + 48  # positions data
    b = bytearray(golden)
    b[p + 4:p + 8] = np.array([np.nan], "<f4").tobytes()
    _fail(b, "group0.link0.mesh0.chunk0: positions contain NaN", "chunk0.positions")


def test_strip_lengths_disagree(golden):
    _, c, o = _first_chunk(golden)
    b = bytearray(golden)
    b[o + 64:o + 68] = np.array([int(c.strip_lengths[0]) + 1], "<u4").tobytes()
    _fail(b, "strip lengths sum to", "chunk0.strip_lengths")


def test_huge_vertex_count(golden):
    _, c, o = _first_chunk(golden)
    b = bytearray(golden)
    b[o + 60:o + 64] = np.array([10 ** 8], "<u4").tobytes()
    _fail(b, "vertex count 100000000", "chunk0.vertex_count")


def test_not_a_chunk(golden):
    _, c, o = _first_chunk(golden)
    b = bytearray(golden)
    b[o + 31] = 0x00
    _fail(b, "no chunk at blob offset", "chunk0.preamble")


def test_slot_outside_the_reference_list(golden):
    _, c, o = _first_chunk(golden)
    b = bytearray(golden)
    uv = o + 64 + 16 * len(c.strip_lengths) + 16 + 48  # strips, DMA CNT quadword, section header
    b[uv + 4:uv + 6] = np.array([14 + 4 * 200], "<i2").tobytes()
    _fail(b, "weight slot 200 is outside", "chunk0.uv")


def test_read_errors(tmp_path):
    with pytest.raises(FormatError, match="cannot read"):
        read_mpf(tmp_path / "missing.mpf")
    with pytest.raises(FormatError, match="is a folder, expected a file|not a regular file"):
        read_mpf(tmp_path)


def test_writer_refuses_bad_values(golden):
    f = parse_mpf(golden)
    f.models[0].palettes[0]["weight"][0] += 5
    with pytest.raises(ValidationError, match="sums to"):
        mpf_bytes(f)
    g = parse_mpf(golden)
    g.models[0].groups[0].links[0].meshes[0].chunks[0].positions[0, 0] = np.inf
    with pytest.raises(ValidationError, match="NaN or infinity"):
        mpf_bytes(g)


# ------------------------------------------------------------------------------------ hypothesis
@st.composite
def models(draw):
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31)))
    n_bones = draw(st.integers(1, 6))
    bones = np.zeros(n_bones, BONE_DTYPE)
    bones["name"] = [f"b{i}".encode() for i in range(n_bones)]
    bones["parent_bone"] = np.arange(n_bones) - 1
    bones["parent_file"] = np.where(np.arange(n_bones) > 0, 0, -1)
    bones["translation"] = rng.normal(size=(n_bones, 3)) * 10
    bones["rotation"] = rng.uniform(-3, 3, (n_bones, 3))
    pals = []
    for _ in range(draw(st.integers(1, 5))):
        k = int(rng.integers(1, 4))
        cuts = np.sort(rng.choice(np.arange(1, 4), k - 1, replace=False)) if k > 1 else np.array([], int)
        units = np.diff(np.concatenate([[0], cuts, [4]]))
        pals.append(np.array([(25 * int(u), int(rng.integers(n_bones)), 0) for u in units], PALETTE_ENTRY_DTYPE))
    n_keys = draw(st.integers(0, 2))
    groups = []
    for gi in range(draw(st.integers(1, 3))):
        links = []
        for _ in range(draw(st.integers(1, 2))):
            refs = rng.choice(len(pals), int(rng.integers(1, len(pals) + 1)), replace=False).astype("<u4")
            n = int(draw(st.integers(3, 140)))
            slot = rng.integers(0, len(refs), n)
            uv = np.zeros((n, 4), "<i2")
            uv[:, :2] = rng.integers(-4096, 8192, (n, 2))
            uv[:, 2], uv[:, 3] = 14 + 4 * slot, 114 + 3 * slot
            nrm = rng.integers(-32768, 32767, (n, 3)).astype("<i2")
            pos = (rng.normal(size=(n, 3)) * 100).astype("<f4")
            shadow = draw(st.booleans()) and gi == 2
            cuts = np.sort(rng.choice(np.arange(1, n), int(rng.integers(0, min(4, n - 1))), replace=False))
            strips = [s for s in np.split(np.arange(n), cuts) if s.size >= 3] or [np.arange(n)]
            if shadow:
                chunks = pack_chunks(strips, None, None, pos, shadow_slots=(14 + 4 * slot).astype("<u4"))
                links.append(Link([Mesh(chunks)], refs))
            elif gi == 1 and n_keys:
                chunks, idx = pack_chunks(strips, uv, nrm, pos, return_index=True)
                links.append(Link([Mesh([c], morphs=[MorphKey(rng.integers(-128, 128, (c.n_vertices, 3)).astype("i1"))
                                                     for _ in range(n_keys)]) for c in chunks], refs))
            else:
                links.append(Link([Mesh(pack_chunks(strips, uv, nrm, pos))], refs))
        groups.append(Group([1, 256, 17][gi], 0, links, unknown=int(rng.integers(0, 2 ** 31))))
    sub = SubModel(name=draw(st.sampled_from(["Body3000", "Head3000", "Face3000", "x"])), file_id=draw(st.integers(-128, 127)),
                   bones=bones, palettes=pals, groups=groups, morph_keys=n_keys if len(groups) > 1 else 0)
    if len(groups) < 2:
        sub.morph_keys = 0
    return MpfFile([sub])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models())
def test_hypothesis_round_trip(f):
    b = mpf_bytes(f)
    g = parse_mpf(b)
    assert mpf_bytes(g) == b
    a, s = f.models[0], g.models[0]
    assert s.file_id == a.file_id and np.array_equal(s.bones, a.bones)
    for la, lb in zip(a.links, s.links):
        assert np.array_equal(la.refs, lb.refs)
        for ma, mb in zip(la.meshes, lb.meshes):
            for ca, cb in zip(ma.chunks, mb.chunks):
                assert np.array_equal(ca.positions, cb.positions) and np.array_equal(ca.slots, cb.slots)
            for ka, kb in zip(ma.morphs, mb.morphs):
                assert np.array_equal(ka.deltas, kb.deltas)
    for x in g.models:
        x.source = None
    assert mpf_bytes(g) == b


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_hypothesis_corruption_gives_format_errors(golden, data):
    """Any corrupted byte run either still parses or raises FormatError (never IndexError, struct,
    numpy or MemoryError)."""
    b = bytearray(golden)
    n = data.draw(st.integers(1, 4))
    for _ in range(n):
        at = data.draw(st.integers(0, len(b) - 1))
        run = data.draw(st.binary(min_size=1, max_size=8))
        b[at:at + len(run)] = run
    if data.draw(st.booleans()):
        b = b[:data.draw(st.integers(0, len(b)))]
    try:
        f = parse_mpf(bytes(b), "fuzz.mpf")
    except FormatError:
        return
    assert mpf_bytes(f) == bytes(b)


# real files: tests/formats/ssx/test_mpf_real_files.py (PISTE_SSX_TRICKY_DIR)


@st.composite
def skinned_models(draw):
    """A random chain skeleton and a random grid mesh with up to 4 random influences a vertex
    (many distinct combinations: several links of <= 25 palettes, long strips cut into chunks)."""
    from piste.character.model import Model, Skeleton, SkinnedMesh

    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31)))
    nb = draw(st.integers(2, 12))
    t = rng.normal(size=(nb, 3)) * 0.1
    t[0] = 0
    world = np.cumsum(t, axis=0)
    ib = np.tile(np.eye(4), (nb, 1, 1))
    ib[:, :3, 3] = -world
    sk = Skeleton([f"j{i}" for i in range(nb)], np.arange(nb) - 1, t, np.tile([0, 0, 0, 1.0], (nb, 1)),
                  np.ones((nb, 3)), ib)
    gx, gy = draw(st.integers(2, 30)), draw(st.integers(2, 12))
    y, x = np.mgrid[0:gy, 0:gx]
    pos = np.stack([x * 0.05, y * 0.05, rng.normal(size=x.shape) * 0.01], -1).reshape(-1, 3)
    q = (y[:-1, :-1] * gx + x[:-1, :-1]).ravel()
    tri = np.concatenate([np.stack([q, q + 1, q + gx], 1), np.stack([q + 1, q + gx + 1, q + gx], 1)])
    v = len(pos)
    joints = rng.integers(0, nb, (v, 4))
    w = rng.random((v, 4)) * (rng.random((v, 4)) < 0.6)
    w[:, 0] += 0.05
    w /= w.sum(1, keepdims=True)
    mesh = SkinnedMesh("m", pos, tri, uv=rng.random((v, 2)), joints=joints, weights=w, skinned=True)
    return Model("rand", skeleton=sk, meshes=[mesh])


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(skinned_models())
def test_hypothesis_encode_decode(model):
    from piste.character import palette
    from piste.formats.ssx.mpf import game_limits
    from piste.formats.ssx.mpf_encode import model_to_mpf
    from piste.formats.ssx.mpf_model import mpf_to_model

    f, r = model_to_mpf(model, ratios=(1.0,), names=("Body3000",), shadow=None)
    assert game_limits(f) == [] and r["max_bind_error_m"] < 1e-6
    b = mpf_bytes(f)
    m = mpf_to_model(parse_mpf(b))
    src = model.meshes[0]
    got = m.lods[0].mesh
    assert got.n_triangles == src.n_triangles
    # every decoded vertex is a source vertex with the source's quantised weights
    from scipy.spatial import cKDTree

    d, j = cKDTree(src.positions).query(got.positions)
    assert d.max() < 1e-6
    pb, pw = palette(src, 0.25, 3).vertex_weights()
    gb, gw = m.lods[0].palette.vertex_weights()
    nb = model.skeleton.n_bones
    dense = lambda b_, w_, n: np.add.at(z := np.zeros((n, nb)), (np.repeat(np.arange(n), b_.shape[1]), b_.reshape(-1)),  # noqa: E731
                                        w_.reshape(-1)) or z
    assert np.allclose(dense(gb, gw, len(gb)), dense(pb, pw, len(pb))[j], atol=1e-6)


def test_write_is_atomic(golden, tmp_path):
    from piste.formats.ssx.mpf import write_mpf

    out = tmp_path / "RIDER.mpf"
    out.write_bytes(b"previous")
    f = parse_mpf(golden)
    f.models[0].palettes[0]["weight"][0] += 1
    with pytest.raises(ValidationError):
        write_mpf(f, out)
    assert out.read_bytes() == b"previous" and [p.name for p in tmp_path.iterdir()] == ["RIDER.mpf"]
