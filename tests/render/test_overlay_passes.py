"""The view overlay's per-pass bars (--trace): StatsHistory.passes and pass_bars."""

from __future__ import annotations

import numpy as np

from piste.render.overlay import StatsHistory, overlay_image, pass_bars


class _Frame:
    kind_counts = {4: 10, 6: 5, 8: 2, 0: 1, -1: 0}
    patches, patches_total, triangles, timings = 18, 64, 900, {"tessellate": 0.2}


def test_passes_are_averaged_and_drawn_as_bars_under_the_table():
    h = StatsHistory(8)
    h.add(_Frame(), 10.0, {})
    plain = overlay_image(h, "x")
    assert h.passes() == {}
    h.add(_Frame(), 10.0, {"passes": {"terrain": (1.0, 4.0), "riders": (0.5, 1.0)}})
    h.add(_Frame(), 10.0, {"passes": {"terrain": (3.0, 6.0), "riders": (0.5, 3.0)}})
    assert h.passes() == {"terrain": (2.0, 5.0), "riders": (0.5, 2.0)}
    img = overlay_image(h, "x")
    bars = pass_bars(h.passes(), plain.shape[1])
    assert img.shape[0] == plain.shape[0] + bars.shape[0] and img.shape[1] == plain.shape[1]
    assert np.array_equal(img[plain.shape[0]:], bars)
    orange = (bars[..., 0] == 255) & (bars[..., 1] == 170) & (bars[..., 2] == 60)
    rows = np.nonzero(orange.any(axis=1))[0]
    terrain_len, riders_len = (np.count_nonzero(orange[r]) for r in (rows.min(), rows.max()))
    assert terrain_len > 2 * riders_len  # 5 ms against 2 ms, to one scale
