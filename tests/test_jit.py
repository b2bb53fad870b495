"""piste._jit: the background numba warm-up and the holds that keep it back (a fresh process's
first frame)."""

from __future__ import annotations

from types import SimpleNamespace

from piste import _jit


class _FakeThread:
    started: list = []

    def __init__(self, target, name, daemon):
        self.name = name

    def start(self):
        _FakeThread.started.append(self.name)


def fake_warm_up_state(monkeypatch) -> list:
    """Fresh warm-up state with a thread class that only records that it was started."""
    started = []
    monkeypatch.setattr(_FakeThread, "started", started)
    monkeypatch.setattr(_jit, "HAVE_NUMBA", True)
    monkeypatch.setattr(_jit, "_THREAD", [None])
    monkeypatch.setattr(_jit, "_HOLDS", [0, False])
    monkeypatch.setattr(_jit, "threading", SimpleNamespace(Thread=_FakeThread))
    return started


def test_warm_up_starts_when_the_last_hold_is_released(monkeypatch):
    started = fake_warm_up_state(monkeypatch)
    a, b = _jit.WarmUpHold(), _jit.WarmUpHold()
    _jit.warm_up_async()
    _jit.warm_up_async()
    assert started == []
    a.release()
    a.release()  # idempotent: b still holds
    assert started == []
    b.release()
    assert started == ["piste-numba-warm-up"]
    _jit.warm_up_async()  # once per process
    assert started == ["piste-numba-warm-up"]


def test_a_hold_released_without_a_request_starts_nothing(monkeypatch):
    started = fake_warm_up_state(monkeypatch)
    _jit.WarmUpHold().release()
    assert started == []
    _jit.warm_up_async()  # no hold: at once
    assert started == ["piste-numba-warm-up"]


def test_a_hold_dropped_without_start_leaves_the_request_to_the_next_ask(monkeypatch):
    started = fake_warm_up_state(monkeypatch)
    hold = _jit.WarmUpHold()
    _jit.warm_up_async()
    hold.release(start=False)
    assert started == []
    _jit.warm_up_async()  # (a kernel's ready() asks again)
    assert started == ["piste-numba-warm-up"]
