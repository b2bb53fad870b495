"""The compiled CPU tessellation path (numba: ``_kernels.tess_frame``) against the numpy path, field
by field and bit for bit, and the pieces it relies on (shape registry, bitwise UV snapshots)."""

import numpy as np
import pytest

from piste import _jit
from piste.errors import ValidationError
from piste.terrain import PatchNet, _kernels, tessellate
from piste.terrain.tessellate import _cache, _Snapshot

from nets import TEAPOT, grid_net
from test_tessellate import check_crack_free

FIELDS = ("positions", "normals", "uv", "uv_lightmap", "uv_projected", "param", "indices", "patch_ids", "patch_kind",
          "patch_levels", "vertex_patch", "vertex_start", "tri_start", "strips")

needs_numba = pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not installed: only the numpy path exists")
BOTH = [pytest.param(True, marks=needs_numba, id="numba"), pytest.param(False, id="numpy")]


@pytest.fixture(scope="module", autouse=True)
def compiled():
    _jit.warm_up()
    if _kernels.HAVE_NUMBA:
        assert _kernels.tess_ready()  # else use_numba=None below would run numpy


def assert_same(a, b):
    for k in FIELDS:
        x, y = getattr(a, k), getattr(b, k)
        if x is None or y is None:
            assert x is None and y is None, k
            continue
        assert x.dtype == y.dtype and x.shape == y.shape, (k, x.dtype, y.dtype, x.shape, y.shape)
        assert x.dtype.isbuiltin == y.dtype.isbuiltin == 1, k  # numpy's own dtype objects (vispy counts on it)
        assert x.tobytes() == y.tobytes(), k


def n_levels_present(levels) -> int:
    return len(np.unique(levels))


@needs_numba
@pytest.mark.parametrize("choices", [(4, 6, 8), (2, 3, 4, 5, 6, 7, 8), tuple(range(2, 65)), (6,), (2, 8)])
@pytest.mark.parametrize("seed", range(3))
def test_compiled_bit_identical_to_numpy(choices, seed):
    """Every field, for every patch subset shape: all patches, a shuffled subset with repeats, one.
    (Many levels: a small net, the vertex cache holds every level: ~30 MB for 2..64 and 6 patches.)"""
    net = grid_net(6, 7, seed=seed) if len(choices) <= 8 else grid_net(2, 3, seed=seed)
    rng = np.random.default_rng(seed)
    levels = rng.choice(choices, net.n_edges).astype(np.int16)
    subsets = (None, rng.integers(0, len(net), 2 * len(net)), [int(rng.integers(len(net)))])
    for patches in subsets:
        for strips in (False, True):
            a = tessellate(net, levels, patches=patches, strips=strips)  # compiled (warmed up)
            b = tessellate(net, levels, patches=patches, strips=strips, use_numba=False)
            c = tessellate(net, levels, patches=patches, strips=strips, use_numba=True)
            assert_same(a, b)
            assert_same(c, b)


@needs_numba
def test_both_sorts_of_the_compiled_plan_are_exercised():
    """Few levels present: counting sort on ranked keys; many: the stable argsort.  Both orders must
    equal numpy's stable argsort of the full keys (checked above); here: both branches are reached."""
    rng = np.random.default_rng(1)
    for choices, counting in (((4, 6, 8), True), (tuple(range(2, 65)), False)):
        net = grid_net(6, 7, seed=1) if counting else grid_net(2, 3, seed=1)
        levels = rng.choice(choices, net.n_edges)
        assert (2 * n_levels_present(levels) ** 5 <= 65536) == counting
        assert_same(tessellate(net, levels, use_numba=True), tessellate(net, levels, use_numba=False))


@pytest.mark.parametrize("use_numba", BOTH)
def test_teapot_both_paths_crack_free(use_numba):
    """A closed model with collapsed edges (degenerate patches): both cached paths crack-free."""
    net = PatchNet.from_bpt(TEAPOT)
    for seed in range(3):
        levels = np.random.default_rng(seed).choice([4, 6, 8], net.n_edges)
        mesh = tessellate(net, levels, use_numba=use_numba)
        check_crack_free(net, levels, mesh)
        if _kernels.HAVE_NUMBA:
            assert_same(mesh, tessellate(net, levels, use_numba=not use_numba))


@pytest.mark.parametrize("use_numba", BOTH)
def test_cached_paths_match_evaluation(use_numba):
    """Compiled and numpy cached paths against the frame evaluated from scratch (an independent
    route): corners and edges bit for bit, inner points to float32 rounding."""
    net = grid_net(4, 5, seed=3)
    levels = np.random.default_rng(3).choice([3, 4, 6, 8], net.n_edges)
    a = tessellate(net, levels, cache=False)
    b = tessellate(net, levels, use_numba=use_numba)
    for f in ("param", "indices", "patch_ids", "patch_levels", "patch_kind", "vertex_patch", "tri_start"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    on_edge = (a.param == 0).any(axis=1) | (a.param == 1).any(axis=1)
    assert np.array_equal(a.positions[on_edge], b.positions[on_edge])
    assert np.allclose(a.positions, b.positions, atol=1e-5) and np.allclose(a.normals, b.normals, atol=1e-5)
    assert np.allclose(a.uv_lightmap, b.uv_lightmap, atol=1e-6)


@pytest.mark.parametrize("use_numba", BOTH)
@pytest.mark.parametrize("levels, patches, match", [
    (1, None, "2..64"), (65, None, "2..64"), (np.full(3, 4), None, "one per edge"),
    (4, [0, -1], "patch ids"), (4, [10**6], "patch ids"),
])
def test_bad_input_same_error_on_both_paths(use_numba, levels, patches, match):
    net = grid_net(2, 3)
    with pytest.raises(ValidationError, match=match):
        tessellate(net, levels, patches=patches, use_numba=use_numba)


@needs_numba
def test_bad_levels_reported_alike():
    net = grid_net(2, 3)
    lv = np.full(net.n_edges, 4)
    lv[3] = 70
    msgs = []
    for use_numba in (True, False):
        with pytest.raises(ValidationError) as e:
            tessellate(net, lv, use_numba=use_numba)
        msgs.append(str(e.value))
    assert msgs[0] == msgs[1] and "4..70" in msgs[0]


LAYOUTS = {
    "permuted": lambda uv: np.ascontiguousarray(uv.transpose(1, 0, 2)).transpose(1, 0, 2),  # as the course's
    "not dense": lambda uv: np.repeat(uv, 2, axis=2)[:, :, ::2],  # compared in Python, not by the kernel
    "C": np.ascontiguousarray,
}


@pytest.mark.parametrize("use_numba", BOTH)
@pytest.mark.parametrize("layout", LAYOUTS)
def test_vertex_cache_follows_in_place_uv_edits(use_numba, layout):
    """One changed UV (a single-ulp edit, in place, whatever the array's layout) rebuilds the cache."""
    net = grid_net(3, 3, flips=False)
    net.uv = LAYOUTS[layout](net.uv)
    assert np.array_equal(net.uv, grid_net(3, 3, flips=False).uv)
    before = tessellate(net, 4, use_numba=use_numba).uv.copy()
    net.uv[4, 2, 1] = np.nextafter(net.uv[4, 2, 1], np.float32(2))
    after = tessellate(net, 4, use_numba=use_numba)
    assert not np.array_equal(before, after.uv)
    assert np.array_equal(after.uv, tessellate(net, 4, cache=False).uv)
    net.lightmap_rect[:] = [0.25, 0.25, 0.5, 0.5]
    assert np.array_equal(tessellate(net, 4, use_numba=use_numba).uv_lightmap,
                          tessellate(net, 4, cache=False).uv_lightmap)
    assert not _cache(net).uv_changed(net)


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 64, 1001])
def test_same_bytes_compiled_and_numpy(n):
    rng = np.random.default_rng(n)
    a = rng.integers(0, 256, n, dtype=np.uint8)
    paths = [False, True] if _kernels.HAVE_NUMBA else [False]
    for use in paths:
        assert _kernels.same_bytes(a, a.copy(), use_numba=use)
        assert not _kernels.same_bytes(a, a[:-1].copy() if n else np.zeros(1, np.uint8), use_numba=use)
        for i in {0, n // 2, n - 1} if n else ():
            b = a.copy()
            b[i] ^= 1 << int(rng.integers(8))
            assert not _kernels.same_bytes(a, b, use_numba=use), (use, i)


@pytest.mark.parametrize("make", [
    lambda a: a,  # C order
    lambda a: np.asfortranarray(a),
    lambda a: np.ascontiguousarray(a.transpose(1, 0, 2)).transpose(1, 0, 2),  # dense, permuted axes
    lambda a: np.ascontiguousarray(np.repeat(a, 2, axis=2))[:, :, ::2],  # not dense: full comparison
])
def test_snapshot_detects_every_change(make):
    a = make(np.arange(24, dtype=np.float32).reshape(3, 4, 2))
    snap = _Snapshot(a)
    assert snap.same(a) and snap.same(make(a.copy()))
    a[2, 3, 1] = -a[2, 3, 1]
    assert not snap.same(a)
    a[2, 3, 1] = -a[2, 3, 1]
    assert snap.same(a)
    assert not snap.same(a.astype(np.float64))
    assert not snap.same(a[:2])


@needs_numba
def test_read_only_inputs_use_the_warmed_kernels():
    """Read-only levels / patch ids (numba types them apart) run the already compiled signatures."""
    net = grid_net(3, 4, seed=2)
    levels = np.random.default_rng(2).choice([4, 6, 8], net.n_edges).astype(np.int16)
    pids = np.arange(0, len(net), 2, dtype=np.int64)
    ref = tessellate(net, levels, patches=pids, use_numba=False)
    n_sigs = len(_kernels._tess_frame_nb.compiled.signatures)
    levels.setflags(write=False)
    pids.setflags(write=False)
    assert_same(tessellate(net, levels, patches=pids, use_numba=True), ref)
    assert len(_kernels._tess_frame_nb.compiled.signatures) == n_sigs


@needs_numba
def test_tess_frame_statuses():
    """The kernel reports unknown shapes and a stale vertex cache instead of reading past them."""
    from piste.terrain.tessellate import _SHAPES, key_levels

    net = grid_net(2, 2, seed=4)
    lv = np.full(net.n_edges, 7, np.int16)  # level 7: used by no other test here
    lv[net.side_edge[0, 1]] = 5
    pids = np.arange(len(net), dtype=np.int64)
    empty_registry = (np.zeros(0, np.int64),) * 2 + _SHAPES.arrays[2:]
    u8 = np.zeros(0, np.uint8)
    nothing_built = np.full(65, -1, np.int64)
    grid = np.zeros((0, 14), np.float32)
    out = _kernels.tess_frame(lv, net.side_edge, pids, len(net), 64, empty_registry, nothing_built, grid, (u8,) * 4)
    assert out[0] == _kernels.TESS_NEW_SHAPES
    keys = out[1]
    assert list(keys) == sorted(keys) and {key_levels(int(k)) for k in keys} >= {(7, 7, 7, 7)}
    _SHAPES.add(keys.tolist())
    out = _kernels.tess_frame(lv, net.side_edge, pids, len(net), 64, _SHAPES.arrays, nothing_built, grid, (u8,) * 4)
    assert out[0] == _kernels.TESS_STALE and len(out[7]) == 0
    bad = lv.copy()
    bad[0] = 1
    out = _kernels.tess_frame(bad, net.side_edge, pids, len(net), 64, _SHAPES.arrays, nothing_built, grid, (u8,) * 4)
    assert out[0] == _kernels.TESS_INVALID and list(out[2][:2]) == [1, 7]
    out = _kernels.tess_frame(lv, net.side_edge, pids[:0], len(net), 64, _SHAPES.arrays, nothing_built, grid,
                              (u8,) * 4)
    assert out[0] == _kernels.TESS_EMPTY
    mesh = tessellate(net, lv, use_numba=True)  # registers, builds levels 5 and 7, then draws
    assert_same(mesh, tessellate(net, lv, use_numba=False))


def test_numpy_path_does_not_start_numba():
    """``use_numba=False`` keeps numba out of the process (its import holds the GIL ~0.8 s): the
    vertex cache's per-frame UV check must not start the background warm-up either."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import sys; sys.path.insert(0, %r)\n"
            "from nets import grid_net\n"
            "from piste import _jit\n"
            "from piste.terrain import tessellate\n"
            "net = grid_net(3, 3)\n"
            "for _ in range(3):\n"
            "    tessellate(net, 4, use_numba=False)\n"
            "print(_jit._THREAD[0] is None and 'numba' not in sys.modules)\n") % str(Path(__file__).parent)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True"
