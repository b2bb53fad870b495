"""SSX level patches as an editable control cage, and back (pure Python: no ``bpy``).

The modders' round trip goes through the Multitool project piste writes and reads
(``piste ssx convert LEVEL.pbd --to multitool --out DIR`` / ``piste ssx import DIR --out NEW.pbd``):
``Patches.json`` holds per patch ``Points[16][3]`` (the bicubic Bézier control points, row-major,
game units) and ``UVPoints[4][2]`` (the texture UVs of the corners).  In Blender a level's patches
become one mesh: patch ``k`` is the 4 x 4 grid of vertices ``16 k .. 16 k + 15`` (metres, the
game's units times :data:`GAME_SCALE`, piste's axes, which are Blender's) and 9 quads; its
corner UVs sit on the corner vertices' loops (bilinear in between).  Writing back puts the
vertices' positions and the corner UVs into ``Patches.json``; everything else stays as it was.

API
---
cage_from_patches(patches) -> (verts, faces, uvs)       flat lists for bpy's from_pydata
apply_cage(patches, verts, corner_uvs) -> int           patches changed, in place
load_patches(path) / save_patches(path, doc)
"""

from __future__ import annotations

import json
from pathlib import Path

from .scene_toml import write_if_changed

__all__ = ["GAME_SCALE", "CORNERS", "cage_from_patches", "apply_cage", "load_patches", "save_patches"]

#: metres per SSX Tricky game unit (piste.formats.ssx.pbd.GAME_SCALE)
GAME_SCALE = 0.01
#: control point of each UVPoints corner (row-major 4 x 4)
CORNERS = (0, 3, 12, 15)


def load_patches(path) -> tuple:
    """``(document, patches list)`` of a ``Patches.json`` (``{"Patches": [...]}`` or a bare list)."""
    doc = json.loads(Path(path).read_text())
    patches = doc["Patches"] if isinstance(doc, dict) else doc
    for k, p in enumerate(patches):
        if len(p.get("Points", ())) != 16 or len(p.get("UVPoints", ())) != 4:
            raise ValueError(f"{path}: patch {k}: expected 16 Points and 4 UVPoints")
    return doc, patches


def save_patches(path, doc) -> bool:
    return write_if_changed(path, json.dumps(doc, indent=1).encode())


def cage_from_patches(patches) -> tuple:
    """Vertices (metres), quads and per-loop UVs (one ``(u, v)`` per face corner, faces' order)."""
    verts, faces, uvs = [], [], []
    for k, p in enumerate(patches):
        base = 16 * k
        verts += [tuple(float(c) * GAME_SCALE for c in pt) for pt in p["Points"]]
        corners = [tuple(map(float, uv)) for uv in p["UVPoints"]]
        for r in range(3):
            for c in range(3):
                quad = [(r, c), (r, c + 1), (r + 1, c + 1), (r + 1, c)]
                faces.append(tuple(base + 4 * rr + cc for rr, cc in quad))
                uvs += [_bilinear(corners, rr / 3.0, cc / 3.0) for rr, cc in quad]
    return verts, faces, uvs


def _bilinear(corners, t: float, s: float) -> tuple:
    """UV at row fraction ``t``, column fraction ``s`` from the corners (0,0), (1,0), (0,1), (1,1)."""
    (u00, v00), (u10, v10), (u01, v01), (u11, v11) = corners
    w = ((1 - s) * (1 - t), s * (1 - t), (1 - s) * t, s * t)
    return (w[0] * u00 + w[1] * u10 + w[2] * u01 + w[3] * u11, w[0] * v00 + w[1] * v10 + w[2] * v01 + w[3] * v11)


def apply_cage(patches, verts, corner_uvs=None, tol: float = 0.02) -> int:
    """Put the cage's vertex positions (metres, ``16 n`` of them) and, when given, its corner UVs
    (``n`` lists of 4 ``(u, v)``) into ``patches``; points within ``tol`` game units of the stored
    ones are kept as stored (Blender holds float32 metres: unchanged patches keep their exact floats).  Returns how many patches
    changed."""
    if len(verts) != 16 * len(patches):
        raise ValueError(f"the cage has {len(verts)} vertices, expected 16 per patch = {16 * len(patches)} "
                         "(vertices were added or deleted: edit positions only)")
    changed = 0
    for k, p in enumerate(patches):
        new = [[float(c) / GAME_SCALE for c in verts[16 * k + j]] for j in range(16)]
        moved = any(abs(a - float(b)) > tol for pt, old in zip(new, p["Points"]) for a, b in zip(pt, old))
        uv_moved = False
        if corner_uvs is not None:
            uv = [[float(a), float(b)] for a, b in corner_uvs[k]]
            uv_moved = any(abs(a - float(b)) > 1e-6 for q, old in zip(uv, p["UVPoints"]) for a, b in zip(q, old))
            if uv_moved:
                p["UVPoints"] = uv
        if moved:
            p["Points"] = new
        changed += bool(moved or uv_moved)
    return changed
