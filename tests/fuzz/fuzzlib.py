"""The fuzz harness: hypothesis mutation strategies (byte-wise and structural) and the oracle.

Every case must either load, or raise a :class:`~piste.errors.PisteError` whose message names the
file; anything else (a raw ``KeyError``, a numpy error, a hang, a huge allocation) fails the test.
Each case runs under a time cap (``SIGALRM``) and a memory cap (``RLIMIT_AS`` lowered to the
process's current size + ``MEMORY_CAP`` for the duration of the case, then restored), and a
``MemoryError`` or time-out anywhere in the exception chain is a failure even if a loader turned
it into a ``PisteError``.

Budget: ``PISTE_FUZZ_EXAMPLES=N`` runs N examples per fuzz test (randomised); unset, each test
runs its small default count, derandomised (the same cases every run, so CI is reproducible).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import resource
import signal
import sys
from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from piste.errors import PisteError

REPO = Path(__file__).resolve().parents[2]
DATA = Path(os.environ.get("PISTE_DATA", REPO.parent / "shared" / "data"))
EXAMPLES = REPO / "examples"

FUZZ_EXAMPLES = int(os.environ.get("PISTE_FUZZ_EXAMPLES", "0") or 0)
#: time cap of one case, seconds (a loader that needs more on a small file is a finding)
TIME_CAP = float(os.environ.get("PISTE_FUZZ_TIME_CAP", "10"))
#: memory one case may add to the process (address space), bytes
MEMORY_CAP = int(os.environ.get("PISTE_FUZZ_MEMORY_CAP", str(2 << 30)))

#: cases run, by test (printed at the end of the session by conftest.py)
COUNTS: dict[str, dict[str, int]] = {}


def fuzz_settings(default: int):
    """Hypothesis settings: ``default`` examples (derandomised) or PISTE_FUZZ_EXAMPLES (random)."""
    return settings(
        max_examples=FUZZ_EXAMPLES or default,
        derandomize=not FUZZ_EXAMPLES,
        deadline=None,
        database=None,
        print_blob=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much,
                               HealthCheck.function_scoped_fixture],
    )


class CaseTimeout(BaseException):
    """A case ran past TIME_CAP (a BaseException, so a loader's ``except Exception`` cannot hide it)."""


def _vm_size() -> int:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


@contextlib.contextmanager
def caps(seconds: float = TIME_CAP, memory: int = MEMORY_CAP):
    """Run the body under a time cap and an address-space cap (POSIX; no-op where unavailable)."""

    def alarm(signum, frame):
        raise CaseTimeout(f"case ran past {seconds} s")

    old_handler = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    vm = _vm_size()
    limited = bool(vm) and sys.platform.startswith("linux")
    if limited:
        cap = vm + memory
        resource.setrlimit(resource.RLIMIT_AS, (cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old_handler)
        if limited:
            resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _chain(exc):
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        yield exc
        exc = exc.__cause__ or exc.__context__


def check(loader, path, kind: str, names=None) -> str:
    """Run ``loader(path)`` under the caps: ``"loaded"`` or ``"refused"`` (a PisteError naming the
    file); anything else is raised (fails the test).  ``names``: the text the message must contain
    (default: the file's name)."""
    path = Path(path)
    want = names or path.name
    counts = COUNTS.setdefault(kind, {"cases": 0, "loaded": 0, "refused": 0})
    counts["cases"] += 1
    try:
        with caps():
            loader(path)
    except PisteError as exc:
        for e in _chain(exc):
            if isinstance(e, (MemoryError, CaseTimeout, RecursionError)):
                raise AssertionError(f"{type(e).__name__} hidden inside a PisteError: {exc}") from exc
        assert want in str(exc), f"the error does not name {want!r}: {exc}"
        counts["refused"] += 1
        return "refused"
    counts["loaded"] += 1
    return "loaded"


# ------------------------------------------------------------------------------ byte mutations
def byte_mutations(data: bytes, max_ops: int = 4):
    """Strategy: ``data`` with 1..max_ops byte flips, truncations, insertions, deletions, copies and
    overwrites with boundary values, at positions uniform over the file (hypothesis's own integers
    favour small ones, which would only ever hit a file's header)."""
    n = max(len(data), 1)
    specials = [b"\x00", b"\xff\xff\xff\x7f", b"\xff\xff\xff\xff", b"\x00\x00\x00\x80", b"9999999", b"-1", b"nan"]

    def ops_from(rnd):
        ops = []
        for _ in range(rnd.randint(1, max_ops)):
            kind = rnd.choice(["flip", "truncate", "insert", "delete", "copy", "set"])
            i = rnd.randrange(n)
            arg = {"flip": rnd.randint(1, 255), "truncate": 0, "insert": rnd.randbytes(rnd.randint(1, 32)),
                   "delete": rnd.randint(1, 64), "copy": rnd.randint(1, 256), "set": rnd.choice(specials)}[kind]
            ops.append((kind, i, arg))
        return apply_bytes(data, ops)

    return st.randoms(use_true_random=False).map(ops_from)


def apply_bytes(data: bytes, ops) -> bytes:
    b = bytearray(data)
    for kind, i, arg in ops:
        i = min(i, max(len(b) - 1, 0))
        if kind == "flip" and b:
            b[i] ^= arg
        elif kind == "truncate":
            del b[i:]
        elif kind == "insert":
            b[i:i] = arg
        elif kind == "delete":
            del b[i:i + arg]
        elif kind == "copy":
            b[i:i] = b[i:i + arg]
        elif kind == "set":
            b[i:i + len(arg)] = arg
    return bytes(b)


# ------------------------------------------------------------------------------ structural mutations
DEEP = "__piste_fuzz_deep__"
#: values substituted into documents: wrong types, huge and negative numbers, hostile paths
HOSTILE = [
    None, True, False, 0, -1, 1, 3, 2**31, 2**32 + 1, 2**53 + 1, 2**63 - 1, -(2**63), 10**30,
    1e308, -1e308, 1e-308, 0.5, -0.0, math.inf, -math.inf, math.nan,
    "", "red", "eight", "0", "1e3", "../../../../etc/passwd", "/dev/zero", "/etc/hostname", "data:,",
    "data:application/octet-stream;base64,AAAA", "file:///etc/passwd", "C:\\windows\\x", "a" * 10000,
    [], [None], [1, 2], [1e308, 1e308, 1e308], [-1, -1, -1, -1], [0] * 16, ["a", "b", "c"], [[[]]],
    {}, {"a": None}, {"uri": "../x"}, DEEP,
]


def json_paths(doc, limit: int = 5000) -> list:
    """Paths (tuples of keys / indices) to every value in a JSON document, the root excluded."""
    out, stack = [], [((), doc)]
    while stack and len(out) < limit:
        path, v = stack.pop()
        if isinstance(v, dict):
            items = list(v.items())
        elif isinstance(v, list):
            items = list(enumerate(v))[:64]
        else:
            continue
        for k, x in items:
            out.append(path + (k,))
            stack.append((path + (k,), x))
    return out


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def mutate_doc(doc, ops):
    """Apply structural ``ops`` [(path, action, value)] to a deep copy of ``doc``."""
    doc = json.loads(json.dumps(doc))
    for path, action, value in ops:
        try:
            parent = _get(doc, path[:-1])
            key = path[-1]
            if action == "replace":
                parent[key] = value
            elif action == "delete":
                del parent[key]
            elif action == "grow" and isinstance(parent[key], list):
                parent[key] = parent[key] * 50 if parent[key] else [0] * 50
            elif action == "negate" and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
                parent[key] = -parent[key] - 1
            elif action == "big" and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
                parent[key] = parent[key] * 10**9 + 7
        except (KeyError, IndexError, TypeError):
            continue
    return doc


def doc_mutations(doc, max_ops: int = 3):
    """Strategy: ``doc`` with 1..max_ops values replaced by hostile ones, deleted, grown or scaled."""
    paths = json_paths(doc)
    if not paths:
        return st.just(doc)
    op = st.tuples(st.sampled_from(paths), st.sampled_from(["replace", "replace", "replace", "delete", "grow",
                                                            "negate", "big"]),
                   st.one_of(st.sampled_from(HOSTILE), st.integers(-(2**70), 2**70),
                             st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8)))
    return st.lists(op, min_size=1, max_size=max_ops).map(lambda ops: mutate_doc(doc, ops))


def dump_json(doc) -> bytes:
    """JSON text (NaN/Infinity as Python writes them); DEEP becomes 100,000 nested arrays."""
    text = json.dumps(doc, allow_nan=True)
    return text.replace(json.dumps(DEEP), "[" * 100_000 + "]" * 100_000).encode()


# ------------------------------------------------------------------------------ TOML
def _toml_key(k) -> str:
    k = str(k)
    return k if k and all(c.isalnum() or c in "_-" for c in k) else json.dumps(k)


def _toml_value(v) -> str:
    if v is None:
        return '""'  # TOML has no null: the nearest wrong value
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(max(min(v, 2**63 - 1), -(2**63)))  # TOML integers are 64-bit
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        if v == DEEP:
            return "[" * 5000 + "]" * 5000
        return json.dumps(v, ensure_ascii=True)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return json.dumps(str(v))


def dump_toml(doc: dict) -> bytes:
    """A TOML document of ``doc``, every top-level key on one line (inline tables and arrays)."""
    return ("\n".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in doc.items()) + "\n").encode()
