"""Interlaced video (piste.render.interlace): field times, the weave, the flicker filter and the measure."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.render.interlace import FlickerMeter, field_times, flicker, flicker_filter, interlace, line_alternation, weave


def _bar_video(n=8, h=32, w=24, step=1):
    """A one-line-high white bar moving down ``step`` lines a field: ``2 n`` fields ``(h, w, 3)``."""
    fields = np.zeros((2 * n, h, w, 3), np.uint8)
    for k in range(2 * n):
        fields[k, 4 + k * step, 4:20] = 255
    return fields


def test_field_times_are_half_a_frame_apart():
    assert field_times([0.0, 1 / 30], 30).tolist() == pytest.approx([0.0, 1 / 60, 1 / 30, 1 / 20])
    with pytest.raises(RenderError):
        field_times([0.0], 0)


def test_weave_takes_even_lines_from_the_first_field_and_odd_from_the_second():
    a = np.full((6, 4, 3), 10, np.uint8)
    b = np.full((6, 4, 3), 200, np.uint8)
    out = weave(a, b)
    assert (out[0::2] == 10).all() and (out[1::2] == 200).all()
    assert (weave(a, a) == a).all()  # nothing moved: the progressive frame
    with pytest.raises(RenderError, match="differ in size"):
        weave(a, b[:4])
    with pytest.raises(RenderError, match="odd number"):
        list(interlace([a, b, a]))


def test_the_flicker_filter_is_1_2_1_down_the_columns():
    img = np.zeros((5, 2, 3), np.uint8)
    img[2] = 200
    f = flicker_filter(img)
    assert f[:, 0, 0].tolist() == [0, 50, 100, 50, 0]
    flat = np.full((4, 3, 3), 77, np.uint8)
    assert (flicker_filter(flat) == flat).all()  # flat colour (and the clamped edges) unchanged


def test_line_alternation_of_a_one_line_detail():
    img = np.zeros((1, 5, 1, 3), np.uint8)
    img[0, 2] = 100
    hf = line_alternation(img)
    assert hf.shape == (1, 3, 1) and hf[0, :, 0].tolist() == pytest.approx([-50.0, 100.0, -50.0], abs=1e-3)


def test_interlaced_motion_flickers_and_the_filter_cures_most_of_it():
    fields = _bar_video()
    progressive = fields[0::2]
    raw = np.stack(list(interlace(fields)))
    filtered = np.stack(list(interlace(fields, filtered=True)))
    f_prog, f_raw, f_filt = flicker(progressive), flicker(raw), flicker(filtered)
    assert f_raw > 0 and f_filt < 0.5 * f_raw, (f_prog, f_raw, f_filt)
    # only the lines the bar crossed differ from the progressive frames
    diff = (raw != progressive).any(axis=(0, 2, 3))
    assert not diff[:4].any() and not diff[4 + 2 * len(fields):].any()
    with pytest.raises(RenderError, match="at least 2"):
        flicker(raw[:1])


def test_the_meter_measures_a_video_frame_by_frame_as_flicker_does():
    raw = np.stack(list(interlace(_bar_video())))
    m = FlickerMeter()
    assert m.value is None
    for f in raw:
        m.add(f)
    assert m.pairs == len(raw) - 1 and m.value == pytest.approx(flicker(raw), rel=1e-5)
    with pytest.raises(RenderError, match="sizes differ"):
        m.add(raw[0, :10])
