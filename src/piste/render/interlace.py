"""Broadcast video: the PS2's interlaced field rendering, its flicker and the flicker filter.

A PS2 game on a television drew **fields**, not frames: 50 (PAL) or 60 (NTSC) a second, each
shown on every other scan line, the even lines of one field and the odd lines of the next woven
into the picture the eye sees.  Time advances half a frame between the two fields, so whatever
moves is drawn at two places on alternate lines (combing), and any detail one line high - a
silhouette's edge, a thin rail, the horizon - is lit on one field and dark on the next: it
flickers at 25/30 Hz.  The standard cure (what SSX and most PS2 games did in their frame-buffer
copy to the display) was a vertical **flicker filter**: each field blurred [1 2 1] / 4 across
lines before it is shown, so no detail is one line high.

* :func:`field_times` - the two field times of each output frame (``t`` and ``t + 0.5 / fps``);
* :func:`flicker_filter` - the vertical [1 2 1] / 4 filter of one field;
* :func:`weave` - an output frame: even lines from the first field, odd lines from the second;
* :func:`interlace` - fields (an iterator, two per frame) -> woven frames;
* :func:`line_alternation` / :func:`flicker` - the measure: per frame, the line-alternating
  component (each row minus the mean of the rows above and below, on luminance), and the mean
  energy of its change between consecutive frames.

API
---
::

    field_times(times, fps) -> (2n,) float64                   t0, t0 + 1/(2 fps), t1, ...
    flicker_filter(image) -> (H, W, C) uint8                     vertical [1 2 1] / 4, edges clamped
    weave(first, second, filtered=False) -> (H, W, C) uint8
    interlace(fields, filtered=False) -> iterator of frames     two fields per frame
    line_alternation(frames) -> (n, H - 2, W) float32
    flicker(frames) -> float                                    mean squared frame-to-frame change
    FlickerMeter()        ``.add(frame)`` one frame at a time (a long video), ``.value`` = flicker(frames so far)
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np
import numpy.typing as npt

from piste.errors import RenderError

__all__ = ["field_times", "flicker_filter", "weave", "interlace", "line_alternation", "flicker", "FlickerMeter"]

#: Rec. 601 luma weights (the PS2's video encoder's)
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def field_times(times: npt.ArrayLike, fps: float) -> np.ndarray:
    """``(2n,) float64``: each output frame time ``t`` followed by its second field's, ``t + 0.5 / fps``
    (fields at twice the frame rate: 60 a second for 30 fps video)."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if not (np.isfinite(fps) and fps > 0):
        raise RenderError(f"interlace: fps must be a positive number, got {fps!r}")
    return np.stack([t, t + 0.5 / float(fps)], axis=1).reshape(-1)


def _check(image: npt.ArrayLike, what: str) -> np.ndarray:
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[0] < 2:
        raise RenderError(f"interlace: {what} must be an (H, W, C) uint8 image with H >= 2, "
                          f"got {img.shape} {img.dtype}")
    return img


def flicker_filter(image: npt.ArrayLike) -> np.ndarray:
    """``(H, W, C) uint8``: ``image`` filtered [1 2 1] / 4 down its columns (rounded; the first and
    last rows use themselves as the missing neighbour)."""
    img = _check(image, "a field").astype(np.uint16)
    up = np.concatenate([img[:1], img[:-1]], axis=0)
    down = np.concatenate([img[1:], img[-1:]], axis=0)
    return ((up + 2 * img + down + 2) >> 2).astype(np.uint8)


def weave(first: npt.ArrayLike, second: npt.ArrayLike, filtered: bool = False) -> np.ndarray:
    """One output frame ``(H, W, C) uint8``: the even lines (0, 2, ...) from field ``first``, the odd
    lines from field ``second`` (each flicker-filtered first when ``filtered``)."""
    a = _check(first, "the first field")
    b = _check(second, "the second field")
    if a.shape != b.shape:
        raise RenderError(f"interlace: the fields differ in size: {a.shape} and {b.shape}")
    if filtered:
        a, b = flicker_filter(a), flicker_filter(b)
    out = a.copy()
    out[1::2] = b[1::2]
    return out


def interlace(fields: Iterable[npt.ArrayLike], filtered: bool = False) -> Iterator[np.ndarray]:
    """Woven frames from ``fields`` (two per frame, in time order: :func:`field_times`); an odd
    field at the end is an error (a frame needs both)."""
    it = iter(fields)
    for first in it:
        second = next(it, None)
        if second is None:
            raise RenderError("interlace: an odd number of fields (each frame needs two)")
        yield weave(first, second, filtered)


def line_alternation(frames: npt.ArrayLike) -> np.ndarray:
    """``(n, H - 2, W) float32``: each frame's line-alternating component, luminance row ``i`` minus
    the mean of rows ``i - 1`` and ``i + 1`` (``frames``: ``(n, H, W, 3)`` uint8 or a list of them)."""
    f = np.asarray(frames)
    if f.ndim != 4 or f.shape[-1] < 3 or f.shape[1] < 3:
        raise RenderError(f"flicker: frames must be (n, H, W, 3) with H >= 3, got {f.shape}")
    y = f[..., :3].astype(np.float32) @ _LUMA
    return y[:, 1:-1] - 0.5 * (y[:, :-2] + y[:, 2:])


def flicker(frames: npt.ArrayLike) -> float:
    """The flicker of a video ``(n, H, W, 3)`` (n >= 2): the mean over consecutive frame pairs and
    pixels of the squared change of :func:`line_alternation` (luma levels squared)."""
    hf = line_alternation(frames)
    if len(hf) < 2:
        raise RenderError(f"flicker: needs at least 2 frames, got {len(hf)}")
    return float(np.mean(np.square(np.diff(hf, axis=0))))


class FlickerMeter:
    """:func:`flicker` over a video seen one frame at a time (only the last frame's component kept)."""

    def __init__(self) -> None:
        self._last: np.ndarray | None = None
        self._sum = 0.0
        self.pairs = 0

    def add(self, frame: npt.ArrayLike) -> None:
        """One more frame ``(H, W, 3) uint8``."""
        hf = line_alternation(np.asarray(frame)[None])[0]
        if self._last is not None:
            if hf.shape != self._last.shape:
                raise RenderError(f"flicker: frame sizes differ: {hf.shape} and {self._last.shape}")
            self._sum += float(np.mean(np.square(hf - self._last), dtype=np.float64))
            self.pairs += 1
        self._last = hf

    @property
    def value(self) -> float | None:
        """The flicker so far (None before two frames)."""
        return self._sum / self.pairs if self.pairs else None
