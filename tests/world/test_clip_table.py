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

