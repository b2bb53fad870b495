"""The compiled blended-palette skinning kernel gives the scipy reference's bits."""

import dataclasses

import numpy as np
import pytest

from piste import _jit
from piste.character import default_rider
from piste.character import skinning
from piste.character.skinning import BlendedMesh


@pytest.mark.skipif(skinning._blend_nb is None, reason="numba not installed: only the scipy/numpy path exists")
@pytest.mark.parametrize("normalize", [True, False])
def test_compiled_blend_bit_identical_to_sparse(normalize):
    _jit.warm_up()
    assert skinning._blend_nb.ready()  # else the default call below would run numpy
    rider = default_rider()
    sk, me = rider.skeleton, rider.meshes[0]
    mats = np.stack([sk.skin_matrices(rider.clips[n].sample(0.3 * i + 0.1, loop=True))
                     for i, n in enumerate(["ride", "grab", "spin"])])
    bm = BlendedMesh.build(me, 0.25, 3)
    a = bm.apply_many(mats, normalize=normalize)
    b = bm.apply_many(mats, normalize=normalize, use_numba=False)
    assert a[0].dtype == np.float32 and a[0].shape == (3, me.n_vertices, 3)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    one = bm.apply(mats[1], normalize=normalize)
    ref = bm.apply(mats[1], normalize=normalize, use_numba=False)
    assert np.array_equal(one[0], ref[0]) and np.array_equal(one[1], ref[1])



@pytest.mark.skipif(skinning._blend_nb is None, reason="numba not installed: only the scipy/numpy path exists")
@pytest.mark.parametrize("normalize", [True, False])
def test_numpy_path_while_numba_loads_gives_the_compiled_bits(normalize, monkeypatch):
    """A fresh process skins its first frames with numpy while numba loads in the background (no
    scipy matrix built: ``use_numba=None`` and the kernel not ready), then with the kernel.  Both must
    give the same bits, or the riders' pixels change at a moment set by the warm-up's timing: the
    first frames of ``piste render --frames N`` differed from the later ones, and from run to run,
    by up to 145 grey levels (issue 23: an einsum summed in another order, an ulp apart)."""
    _jit.warm_up()
    rider = default_rider()
    sk, me = rider.skeleton, rider.meshes[0]
    mats = np.stack([sk.skin_matrices(rider.clips[n].sample(0.3 * i + 0.1, loop=True))
                     for i, n in enumerate(["ride", "grab", "spin"])])
    bm = BlendedMesh.build(me, 0.25, 3)
    a = bm.apply_many(mats, normalize=normalize, use_numba=True)
    one = bm.apply(mats[1], normalize=normalize, use_numba=True)
    monkeypatch.setattr(skinning._blend_nb, "ready", lambda: False)  # as while numba loads
    b = bm.apply_many(mats, normalize=normalize)
    two = bm.apply(mats[1], normalize=normalize)
    assert bm._sparse is None  # (the path a fresh process takes, not the scipy product)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.array_equal(one[0], two[0]) and np.array_equal(one[1], two[1])
    # the numpy reference without scipy (use_sparse=False) is that same path
    c = BlendedMesh.build(me, 0.25, 3, use_sparse=False).apply_many(mats, normalize=normalize, use_numba=False)
    assert np.array_equal(a[0], c[0]) and np.array_equal(a[1], c[1])


def _six_palettes(bm, rider):
    sk = rider.skeleton
    mats = np.stack([sk.skin_matrices(rider.clips[n].sample(0.2 * i + 0.1, loop=True))
                     for i, n in enumerate(["ride", "crouch", "grab", "spin", "ride", "grab"])])
    return np.ascontiguousarray(bm.palette_matrices(mats), dtype=np.float32)


@pytest.mark.skipif(skinning._blend_nb is None, reason="numba not installed: only the scipy/numpy path exists")
@pytest.mark.parametrize("inverse_transpose", [False, True])
def test_skin_palette_compiled_equals_numpy_twin(inverse_transpose):
    _jit.warm_up()
    rider = default_rider()
    me = rider.meshes[0]
    bm = BlendedMesh.build(me, 0.25, 3)
    pal = _six_palettes(bm, rider)
    a = bm.skin_palette(pal, inverse_transpose=inverse_transpose)
    b = bm.skin_palette(pal, inverse_transpose=inverse_transpose, use_numba=False)
    assert a[0].shape == a[1].shape == (6, me.n_vertices, 3) and a[0].dtype == a[1].dtype == np.float32
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    one = bm.skin_palette(pal[2], inverse_transpose=inverse_transpose)  # one (p, 3, 4) palette -> (v, 3)
    assert np.array_equal(one[0], a[0][2]) and np.array_equal(one[1], a[1][2])
    if not inverse_transpose:  # the talk's 3x3 normals: apply_many is palette_matrices + skin_palette
        st = np.stack([rider.skeleton.skin_matrices(rider.clips["grab"].sample(0.4, loop=True))])
        c, d = bm.apply_many(st), bm.skin_palette(bm.palette_matrices(st))
        assert np.array_equal(c[0], d[0]) and np.array_equal(c[1], d[1])


def test_inverse_transpose_normals_match_float64():
    """Normals by each entry's inverse-transpose (what exact skinning and Panda3D compute), to float32
    precision, on both paths; positions the same as the 3x3 scheme's."""
    rider = default_rider()
    me = rider.meshes[0]
    bm = BlendedMesh.build(me, 0.25, 3)
    pal = _six_palettes(bm, rider)
    a = pal.astype(np.float64)[:, bm.palette.index]  # (6, v, 3, 4)
    ref = np.einsum("nvji,vj->nvi", np.linalg.inv(a[..., :3]), me.normals.astype(np.float64))
    ref /= np.linalg.norm(ref, axis=-1, keepdims=True)
    for use in ([False, None] if skinning._blend_nb is not None else [False]):
        p, n = bm.skin_palette(pal, inverse_transpose=True, use_numba=use)
        assert np.abs(n - ref).max() < 1e-5
        assert np.array_equal(p, bm.skin_palette(pal, use_numba=use)[0])
    plain = bm.skin_palette(pal)[1]
    assert np.abs(plain - ref).max() > 1e-2  # the 3x3 scheme differs where a blend is not a rotation


@pytest.mark.skipif(skinning._blend_nb is None, reason="numba not installed: only the scipy/numpy path exists")
def test_any_vertex_order_gives_the_same_vertices():
    """The compiled kernel walks runs of vertices sharing an entry: a shuffled mesh (runs of ~1 vertex)
    and one sorted by entry (one run per entry) skin to the same vertices as the original order."""
    _jit.warm_up()
    rider = default_rider()
    me = rider.meshes[0]
    bm = BlendedMesh.build(me, 0.25, 3)
    pal = _six_palettes(bm, rider)
    ref = bm.skin_palette(pal, use_numba=False)
    for perm in (np.random.default_rng(3).permutation(me.n_vertices), np.argsort(bm.palette.index, kind="stable")):
        pal_perm = dataclasses.replace(bm.palette, index=bm.palette.index[perm])
        other = BlendedMesh(pal_perm, me.positions[perm], me.normals[perm])
        assert len(other._run_entry) != len(bm._run_entry)
        p, n = other.skin_palette(pal)
        assert np.array_equal(p, ref[0][:, perm]) and np.array_equal(n, ref[1][:, perm])


def test_skin_palette_rejects_a_wrong_palette():
    rider = default_rider()
    bm = BlendedMesh.build(rider.meshes[0], 0.25, 3)
    with pytest.raises(skinning.ValidationError, match="palette"):
        bm.skin_palette(np.zeros((6, bm.palette.size + 1, 3, 4), np.float32))
    with pytest.raises(skinning.ValidationError, match="palette"):
        bm.skin_palette(np.zeros((bm.palette.size, 4, 4), np.float32))
