"""ClipTable.from_samples: a table from pre-sampled clips (a bundle's) plays exactly like one
sampled from the model's curves."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character import default_rider
from piste.errors import ValidationError
from piste.world.riders import ClipTable


def test_from_samples_matches_the_sampled_table():
    model = default_rider()
    ref = ClipTable(model, rate=30.0)
    f = ref.frames
    t = [ref._t[c, : f[c]] for c in range(len(ref.names))]
    r = [ref._r[c, : f[c]] for c in range(len(ref.names))]
    s = [ref._s[c, : f[c]] for c in range(len(ref.names))]
    tab = ClipTable.from_samples(model.skeleton, 30.0, ref.names, ref.duration, t, r, s)
    assert tab.names == ref.names and np.array_equal(tab.frames, ref.frames)
    ids = np.array([0, len(ref.names) - 1, 0])
    times = np.array([0.0, 0.37, 5.3])
    for a, b in zip(tab.local(ids, times), ref.local(ids, times)):
        assert np.array_equal(a, b)
    with pytest.raises(ValidationError, match="rotation has shape"):
        ClipTable.from_samples(model.skeleton, 30.0, ref.names, ref.duration, t, [x[:, :, :3] for x in r], s)
    with pytest.raises(ValidationError, match="same count"):
        ClipTable.from_samples(model.skeleton, 30.0, ref.names[:1], ref.duration, t, r, s)


def test_vectorised_clip_table_equals_pose_by_pose_sampling():
    """ClipTable samples a clip on its own skeleton with one call per track (sample_poses): the same
    bits as Clip.sample one time at a time, hemisphere flips included."""
    from piste.character import default_rider
    from piste.character.animation import sample_poses
    from piste.world.riders import ClipTable

    m = default_rider(0)
    table = ClipTable(m, 60.0)
    for c, name in enumerate(table.names):
        clip = m.clips[name]
        assert clip.skeleton is m.skeleton
        f = int(table.frames[c])
        times = np.minimum(np.arange(f) / 60.0, clip.duration)
        tr, rot, sc = sample_poses(clip, times, m.skeleton)
        for k, t in enumerate(times):
            p = clip.sample(float(t), skeleton=m.skeleton)
            assert np.array_equal(tr[k], p.translation) and np.array_equal(rot[k], p.rotation)
            assert np.array_equal(sc[k], p.scale)
            assert np.array_equal(table._t[c, k], p.translation) and np.array_equal(table._s[c, k], p.scale)
            # the table keeps neighbouring keys in one hemisphere: the same rotation up to sign
            assert np.allclose(np.abs(table._r[c, k]), np.abs(p.rotation), atol=0)


def test_connected_parts_equals_scipy():
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from piste.world.scene import connected_parts

    rng = np.random.default_rng(7)
    graphs = [(1, np.zeros((0, 2), int)), (5, np.array([[0, 0], [1, 2]]))]
    graphs += [(int(n), rng.integers(0, n, (int(k), 2))) for n, k in zip(rng.integers(1, 200, 40), rng.integers(0, 300, 40))]
    n = 3000  # a long shuffled chain: one part
    graphs.append((n, np.stack([np.arange(n - 1), np.arange(1, n)], 1)[rng.permutation(n - 1)]))
    for n, e in graphs:
        k1, l1 = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
        k2, l2 = connected_parts(n, e)
        assert k2 == k1 and len(set(zip(l1.tolist(), l2.tolist()))) == k1  # the same partition
        assert l2.min() == 0 and l2.max() == k2 - 1
        first = [int(np.flatnonzero(l2 == j)[0]) for j in range(k2)]
        assert first == sorted(first)  # numbered by each part's smallest vertex
