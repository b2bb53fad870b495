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
