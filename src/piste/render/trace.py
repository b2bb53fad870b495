"""The performance analyzer (the talk's "Performance analyzer!"): a Chrome / Perfetto trace of every frame.

A :class:`Tracer` is handed to the runtime (``ScenePreview(trace=PATH)``, ``SceneRenderer.tracer``);
the renderer marks its steps with it:

* ``tracer.frame(index)`` - one frame's span (nested calls inside an open frame are no-ops, so the
  command's loop and the renderer may both open it);
* ``tracer.span(name)`` - a CPU step (planning, scene update, terrain LOD, read-back, ...);
* ``tracer.gpu_pass(name)`` - a render pass: its CPU part (issuing the GL calls) as a CPU span and
  its GPU part measured by a GL timer query (``GL_TIME_ELAPSED``, moderngl ``ctx.query(time=True)``),
  resolved when the frame closes (after the renderer's ``glFinish``), so the query never stalls it.

The default :data:`NULL_TRACER` does nothing: its methods return one shared
:func:`contextlib.nullcontext`, so an untraced frame pays a few attribute look-ups per pass.

GPU timing.  A hardware GPU's passes are timed with ``GL_TIME_ELAPSED`` queries.  Mesa's llvmpipe
(the CI / headless renderer) implements them too, but they do not time its passes: it bins draws
and rasterizes them when the frame is flushed, so on the default course's completed scene (30
pipelined frames, 640x448) the queries gave the objects and the riders 0.00 ms and the terrain and
the shadow receivers 8 ms each, while ``glFinish`` brackets gave terrain 10.2, objects 2.8, riders
1.7 ms at the same frame time (20.9 against 21.7 ms a frame; untraced 21.8).  So ``gpu="auto"``
brackets each pass with ``glFinish`` on a software rasterizer (llvmpipe, softpipe, swrast) and uses
the queries elsewhere; ``gpu="query"`` forces the queries (llvmpipe's first one of a context reads
back ``0xFFFFFFFF``: treated as no result, the pass's CPU span stands in), ``gpu="finish"`` the
brackets, also the fallback when a query cannot be made.  ``metadata.gpu_timing`` in the trace
says which was used ("GL_TIME_ELAPSED", "glFinish") and ``metadata.gpu_timing_why`` why; a GPU
span's ``args.source`` says how that span was measured.

Trace layout (the Trace Event Format, JSON object form; opens in ui.perfetto.dev or chrome://tracing)::

    {"traceEvents": [{"name", "ph": "X", "ts" (us), "dur" (us), "pid", "tid", "cat", "args"}, ...
                     {"ph": "M", "name": "thread_name", ...}],
     "displayTimeUnit": "ms", "metadata": {"gpu_timing": ..., "frames": n}}

tid 1 "CPU": ``frame`` spans (cat "frame", ``args.frame``) holding the CPU steps (cat "cpu") and
the passes' CPU parts (cat "pass"); tid 2 "GPU": a ``frame`` span per frame holding the passes' GPU
spans (cat "gpu"), laid end to end from the moment the first pass was issued (a GPU runs the passes
in order; a timer query gives a duration, not a start).

API
---
::

    NULL_TRACER                         the no-op default (``.enabled`` False)
    ChromeTracer(path, ctx=None, gpu="auto")   ``.frame(i)``, ``.span(name)``, ``.gpu_pass(name)``,
                                        ``.last`` {pass: (cpu_ms, gpu_ms)} of the last frame, ``.close()``
    load_trace(path) -> dict            a written trace, checked (TraceError on a malformed one)
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from contextlib import AbstractContextManager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, cast

from piste.errors import PisteError

if TYPE_CHECKING:
    import moderngl

__all__ = ["Tracer", "NULL_TRACER", "ChromeTracer", "TraceError", "load_trace", "make_tracer"]

_NULL = contextlib.nullcontext()
#: what llvmpipe's first timer query of a context reads back: no measurement
_NO_RESULT = 0xFFFFFFFF
_CPU_TID, _GPU_TID = 1, 2
#: GL_RENDERER names of software rasterizers (glFinish-bracketed by default)
_SOFTWARE = ("llvmpipe", "softpipe", "swrast", "software")


class TraceError(PisteError):
    """A trace file that cannot be written or read back."""


class Tracer:
    """The no-op tracer (the runtime's default): every span costs a method call and nothing else."""

    enabled = False
    last: dict = {}

    def frame(self, index: int | None = None) -> AbstractContextManager[Any]:
        return _NULL

    def span(self, name: str, **args: Any) -> AbstractContextManager[Any]:
        return _NULL

    def gpu_pass(self, name: str) -> AbstractContextManager[Any]:
        return _NULL

    def close(self) -> Path | None:
        return None


NULL_TRACER = Tracer()


class _Span:
    """A CPU span: an ``X`` event on the CPU thread when it closes."""

    __slots__ = ("tracer", "name", "cat", "args", "t0")

    def __init__(self, tracer: ChromeTracer, name: str, cat: str, args: dict[str, Any] | None) -> None:
        self.tracer, self.name, self.cat, self.args = tracer, name, cat, args

    def __enter__(self) -> _Span:
        self.t0 = time.perf_counter_ns()
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        t1 = time.perf_counter_ns()
        self.tracer._cpu(self.name, self.cat, self.t0, t1, self.args)
        return False


class _Frame:
    __slots__ = ("tracer", "index", "t0", "outer")

    def __init__(self, tracer: ChromeTracer, index: int) -> None:
        self.tracer, self.index = tracer, index

    def __enter__(self) -> _Frame:
        tr = self.tracer
        self.outer = tr._open is None
        if self.outer:
            tr._open = self
            self.t0 = time.perf_counter_ns()
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        if self.outer:
            self.tracer._close_frame(self, time.perf_counter_ns())
        return False


class _Pass:
    """A render pass: CPU span + a GL timer query (or glFinish brackets)."""

    __slots__ = ("tracer", "name", "t0", "query")

    def __init__(self, tracer: ChromeTracer, name: str) -> None:
        self.tracer, self.name = tracer, name

    def __enter__(self) -> _Pass:
        tr = self.tracer
        self.query = None
        if tr.gpu_timing == "glFinish":
            tr.ctx.finish()
        elif tr.gpu_timing == "GL_TIME_ELAPSED":
            try:
                self.query = tr._free.pop() if tr._free else tr.ctx.query(time=True)
                self.query.__enter__()  # (mglo.begin: GL_TIME_ELAPSED)
            except Exception:  # a context without timer queries: the fallback from here on
                self.query = None
                tr.gpu_timing = "glFinish"
                tr.gpu_timing_why = "a timer query could not be made"
                tr.ctx.finish()
        self.t0 = time.perf_counter_ns()
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        tr = self.tracer
        if self.query is not None:
            self.query.__exit__(None, None, None)
            t1 = time.perf_counter_ns()
            tr._pending.append((self.name, self.t0, t1, self.query))
        else:
            if tr.gpu_timing == "glFinish":
                tr.ctx.finish()
            t1 = time.perf_counter_ns()
            tr._pending.append((self.name, self.t0, t1, None))
        tr._cpu(self.name, "pass", self.t0, t1, None)
        return False


class ChromeTracer(Tracer):
    """Records every frame's CPU steps and GPU passes; :meth:`close` writes the trace to ``path``.

    Parameters
    ----------
    path : the ``.json`` file written (atomically) by :meth:`close`
    ctx : the moderngl context the passes draw with (None: CPU spans only, no GPU spans)
    gpu : "auto" (glFinish brackets on a software rasterizer, else timer queries), "query" or
        "finish" (glFinish brackets: each pass waits for the GPU, so the passes no longer overlap)
    """

    enabled = True

    def __init__(self, path: str | os.PathLike[str], ctx: moderngl.Context | None = None, gpu: str = "auto") -> None:
        if gpu not in ("auto", "query", "finish"):
            raise TraceError(f"{path}: gpu timing must be 'auto', 'query' or 'finish', got {gpu!r}")
        self.path = Path(path)
        # Any: a pass runs only with a context (gpu_pass), and moderngl's Query stub types __exit__'s
        # arguments as tuples
        self.ctx: Any = cast(Any, ctx)
        self.gpu_timing, self.gpu_timing_why = None, "no GL context: CPU spans only"
        if ctx is not None:
            renderer = ""
            with contextlib.suppress(Exception):
                renderer = str(ctx.info.get("GL_RENDERER", ""))
            soft = any(k in renderer.lower() for k in _SOFTWARE)
            if gpu == "finish" or (gpu == "auto" and soft):
                self.gpu_timing = "glFinish"
                self.gpu_timing_why = (f"{renderer}: a software rasterizer's timer queries do not time its passes "
                                       "(it rasterizes at the flush)" if gpu == "auto" else "asked for (gpu='finish')")
            else:
                self.gpu_timing = "GL_TIME_ELAPSED"
                self.gpu_timing_why = "asked for (gpu='query')" if gpu == "query" else f"{renderer}: timer queries"
        self.origin = time.perf_counter_ns()
        self.pid = os.getpid()
        self.events: list[dict] = []
        self._open: _Frame | None = None
        self._pending: list = []
        self._free: list = []  # timer queries read back, ready for another pass
        self._frame_events: list[dict] = []
        self.frames = 0
        self.unmeasured = 0  # GPU spans whose query had no result (their CPU span stands in)
        self.last: dict = {}
        self._closed = False

    # -- recording --------------------------------------------------------------------------
    def frame(self, index: int | None = None) -> _Frame:
        return _Frame(self, self.frames if index is None else int(index))

    def span(self, name: str, **args: Any) -> _Span:
        return _Span(self, name, "cpu", args or None)

    def gpu_pass(self, name: str) -> _Span | _Pass:
        if self.ctx is None:
            return _Span(self, name, "pass", None)
        return _Pass(self, name)

    def _us(self, ns: int) -> float:
        return (ns - self.origin) / 1e3

    def _cpu(self, name: str, cat: str, t0: int, t1: int, args: dict[str, Any] | None) -> None:
        ev = {"name": name, "ph": "X", "ts": self._us(t0), "dur": (t1 - t0) / 1e3, "pid": self.pid,
              "tid": _CPU_TID, "cat": cat}
        if args:
            ev["args"] = args
        self._frame_events.append(ev)

    def _close_frame(self, fr: _Frame, t1: int) -> None:
        self._open = None
        evs, self._frame_events = self._frame_events, []
        if not evs and not self._pending:  # an empty frame (a loop's end): no span
            return
        idx = fr.index
        for ev in evs:
            ev.setdefault("args", {})["frame"] = idx
        self.events.append({"name": "frame", "ph": "X", "ts": self._us(fr.t0), "dur": (t1 - fr.t0) / 1e3,
                            "pid": self.pid, "tid": _CPU_TID, "cat": "frame", "args": {"frame": idx}})
        self.events.extend(evs)
        last: dict[str, Any] = {}
        for ev in evs:
            if ev["cat"] == "pass":
                last[ev["name"]] = [last.get(ev["name"], [0.0, 0.0])[0] + ev["dur"] / 1e3, 0.0]
        # the GPU spans: durations from the queries, end to end from the first pass's issue
        pending, self._pending = self._pending, []
        if pending:
            cursor = self._us(pending[0][1])
            g0 = cursor
            gpu = []
            for name, p0, p1, q in pending:
                source = self.gpu_timing
                if q is not None:
                    ns = int(q.elapsed)  # (the frame was finished: the result is ready)
                    self._free.append(q)  # (moderngl's queries have no release: reused)
                    if ns == _NO_RESULT or ns < 0:
                        ns, source = p1 - p0, "cpu span (no query result)"
                        self.unmeasured += 1
                else:
                    ns = p1 - p0
                start = max(cursor, self._us(p0))
                gpu.append({"name": name, "ph": "X", "ts": start, "dur": ns / 1e3, "pid": self.pid,
                            "tid": _GPU_TID, "cat": "gpu", "args": {"frame": idx, "source": source}})
                cursor = start + ns / 1e3
                last.setdefault(name, [0.0, 0.0])[1] += ns / 1e6
            self.events.append({"name": "frame", "ph": "X", "ts": g0, "dur": cursor - g0, "pid": self.pid,
                                "tid": _GPU_TID, "cat": "frame", "args": {"frame": idx}})
            self.events.extend(gpu)
        self.last = {k: (float(a), float(b)) for k, (a, b) in last.items()}
        self.frames += 1

    # -- output -------------------------------------------------------------------------------
    def trace(self) -> dict:
        """The trace as a Trace Event Format object."""
        meta = [{"name": "process_name", "ph": "M", "pid": self.pid, "tid": 0, "args": {"name": "piste"}},
                {"name": "thread_name", "ph": "M", "pid": self.pid, "tid": _CPU_TID, "args": {"name": "CPU"}},
                {"name": "thread_name", "ph": "M", "pid": self.pid, "tid": _GPU_TID, "args": {"name": "GPU"}}]
        renderer = None
        if self.ctx is not None:
            with contextlib.suppress(Exception):
                renderer = self.ctx.info.get("GL_RENDERER")
        return {"traceEvents": meta + self.events, "displayTimeUnit": "ms",
                "metadata": {"gpu_timing": self.gpu_timing or "none (no GL context)",
                             "gpu_timing_why": self.gpu_timing_why, "gl_renderer": renderer,
                             "frames": self.frames, "gpu_spans_without_query_result": self.unmeasured,
                             "clock": "time.perf_counter_ns, microseconds from the tracer's start"}}

    def close(self) -> Path:
        """Write the trace (atomically: a temporary file renamed into place) and return its path."""
        if self._closed:
            return self.path
        self._closed = True
        data = json.dumps(self.trace())
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(data)
            os.replace(tmp, self.path)
        except OSError as exc:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise TraceError(f"{self.path}: cannot write the trace: {exc.strerror or exc}") from None
        return self.path


def make_tracer(path: str | os.PathLike[str] | None, ctx: moderngl.Context | None = None) -> Tracer:
    """A :class:`ChromeTracer` writing ``path``, or :data:`NULL_TRACER` when ``path`` is None."""
    if path is None:
        return NULL_TRACER
    p = Path(path)
    if p.suffix.lower() != ".json":
        raise TraceError(f"{p}: a trace is a .json file (the Trace Event Format), got {p.suffix or 'no suffix'!r}")
    if p.parent.exists() and not os.access(p.parent, os.W_OK):
        raise TraceError(f"{p}: the folder {p.parent} is not writable")
    return ChromeTracer(p, ctx=ctx)


def load_trace(path: str | os.PathLike[str]) -> dict:
    """A trace file read back and checked: a ``traceEvents`` list whose ``X`` events carry name, ts,
    dur, pid, tid and cat (:class:`TraceError` naming the file and the field otherwise)."""
    p = Path(path)
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError) as exc:
        raise TraceError(f"{p}: not a readable JSON trace: {exc}") from None
    evs = data.get("traceEvents") if isinstance(data, dict) else None
    if not isinstance(evs, list):
        raise TraceError(f"{p}: traceEvents: expected a list of events")
    for i, ev in enumerate(evs):
        if not isinstance(ev, dict) or ev.get("ph") not in ("X", "M"):
            raise TraceError(f"{p}: traceEvents[{i}].ph: expected 'X' or 'M'")
        if ev["ph"] == "X":
            for k in ("name", "ts", "dur", "pid", "tid", "cat"):
                if k not in ev:
                    raise TraceError(f"{p}: traceEvents[{i}].{k}: missing")
            if not (isinstance(ev["dur"], (int, float)) and ev["dur"] >= 0):
                raise TraceError(f"{p}: traceEvents[{i}].dur: expected a duration >= 0 us, got {ev['dur']!r}")
    return data
