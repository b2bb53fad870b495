"""Finding and running the ``piste`` executable (pure Python: no ``bpy``, testable outside Blender).

The add-on never imports piste: Blender's Python is not piste's.  It runs the ``piste`` command
line, found from the add-on preference (the executable itself, or a virtual environment folder
holding ``bin/piste`` / ``Scripts/piste.exe``), else ``$PISTE`` , else ``piste`` on ``PATH``.

API
---
find_piste(setting="") -> str              the executable's path; PisteNotFound says what was tried
run_piste(exe, args, timeout=600) -> str    stdout; PisteFailed carries piste's one-line error
start_piste(exe, args, log_path) -> Popen   a long-running ``piste view``
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

__all__ = ["find_piste", "run_piste", "start_piste", "PisteNotFound", "PisteFailed"]


class PisteNotFound(RuntimeError):
    """No ``piste`` executable where the preference, ``$PISTE`` and ``PATH`` point."""


class PisteFailed(RuntimeError):
    """``piste`` ran and failed: the command and its error output."""


def _candidates(setting: str) -> list:
    out = []
    if setting:
        p = Path(os.path.expanduser(setting))
        if p.is_dir():
            out += [p / "bin" / "piste", p / "Scripts" / "piste.exe", p / "piste"]
        else:
            out.append(p)
    return out


def find_piste(setting: str = "") -> str:
    """The ``piste`` executable: ``setting`` (a file, or a venv folder), ``$PISTE``, then ``PATH``."""
    tried = []
    for p in _candidates(setting):
        tried.append(str(p))
        if p.is_file() and os.access(p, os.X_OK):
            return str(p)
    if setting:
        raise PisteNotFound(f"piste add-on preference 'piste executable' = {setting!r}: no executable piste there "
                            f"(tried {', '.join(tried)}); give the path to 'piste' or to the virtual "
                            "environment piste is installed in (pip install piste)")
    env = os.environ.get("PISTE")
    if env:
        for p in _candidates(env):
            tried.append(str(p))
            if p.is_file() and os.access(p, os.X_OK):
                return str(p)
    found = shutil.which("piste")
    if found:
        return found
    raise PisteNotFound("piste was not found: set Edit > Preferences > Add-ons > piste > 'piste executable' to the "
                        "path of 'piste' or of the virtual environment it is installed in (pip install piste)"
                        + (f"; tried {', '.join(tried)}" if tried else "") + " and PATH")


def run_piste(exe: str, args, timeout: float = 600.0, cwd=None) -> str:
    """Run ``exe args`` to completion; its stdout, or :class:`PisteFailed` with its stderr."""
    cmd = [exe, *map(str, args)]
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd)
    except subprocess.TimeoutExpired:
        raise PisteFailed(f"{' '.join(cmd)}: no answer in {timeout:g} s") from None
    except OSError as exc:
        raise PisteFailed(f"{' '.join(cmd)}: could not start ({exc})") from None
    if r.returncode != 0:
        err = (r.stderr.strip().splitlines() or [f"exit status {r.returncode}"])[-1]
        raise PisteFailed(f"piste {' '.join(map(str, args[:2]))}: {err}")
    return r.stdout


def start_piste(exe: str, args, log_path) -> subprocess.Popen:
    """Start ``exe args`` in the background, its output going to ``log_path``."""
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    log = open(log_path, "w")
    try:
        return subprocess.Popen([exe, *map(str, args)], stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL)
    finally:
        log.close()
