"""Real glTF clients for the export tests: the Khronos validator (node + npm ``gltf-validator`` in
``.tools/``) and Blender (``blender --background``).  A missing tool skips the test, or fails it
when ``PISTE_REQUIRE_TOOLS=1`` (CI)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RUNNER = ROOT / "tools" / "gltf_validate.mjs"
VALIDATOR = ROOT / ".tools" / "node_modules" / "gltf-validator"


def _missing(what: str):
    msg = f"{what} (install with tools/setup-test-tools.sh)"
    if os.environ.get("PISTE_REQUIRE_TOOLS") == "1":
        pytest.fail(f"PISTE_REQUIRE_TOOLS=1 but {msg}")
    pytest.skip(msg)


def validate(*paths) -> list[dict]:
    """Khronos validator reports (one dict per file: errors, warnings, infos, messages)."""
    node = shutil.which("node")
    if node is None:
        _missing("node is not installed")
    if not VALIDATOR.is_dir():
        _missing(f"the gltf-validator npm package is not in {VALIDATOR.parent}")
    r = subprocess.run([node, str(RUNNER), *map(str, paths)], capture_output=True, text=True, timeout=120)
    if r.returncode not in (0, 1):
        raise AssertionError(f"validator runner failed ({r.returncode}): {r.stderr}")
    return [json.loads(line) for line in r.stdout.splitlines() if line.strip()]


def assert_valid(*paths) -> list[dict]:
    reports = validate(*paths)
    assert len(reports) == len(paths)
    for rep in reports:
        errors = [m for m in rep["messages"] if m["severity"] == 0]
        assert rep["errors"] == 0, f"{rep['file']}: {rep['errors']} validator errors: {errors[:5]}"
    return reports


BLENDER_DUMP = r'''
import json, sys
import numpy
if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Debian 12's Blender 3.4 glTF importer uses np.bool, removed in numpy 1.24
import bpy
from mathutils import Vector
src, out = sys.argv[sys.argv.index("--") + 1:]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
d = {"meshes": {}, "armatures": {}, "actions": {}, "lights": {}, "cameras": {}}
for o in bpy.data.objects:
    mw = o.matrix_world
    if o.type == "MESH":
        me = o.data
        d["meshes"][o.name] = {
            "vertices": len(me.vertices), "polygons": len(me.polygons),
            "uv_layers": [l.name for l in me.uv_layers],
            "shape_keys": [k.name for k in me.shape_keys.key_blocks] if me.shape_keys else [],
            "armature": next((m.object.name for m in o.modifiers if m.type == "ARMATURE" and m.object), None),
            "world_min": [min((mw @ v.co)[k] for v in me.vertices) for k in range(3)] if len(me.vertices) else None,
            "world_max": [max((mw @ v.co)[k] for v in me.vertices) for k in range(3)] if len(me.vertices) else None}
    elif o.type == "ARMATURE":
        d["armatures"][o.name] = {"bones": [b.name for b in o.data.bones],
                                  "heads": {b.name: list(mw @ b.head_local) for b in o.data.bones}}
    elif o.type == "LIGHT":
        d["lights"][o.name] = {"type": o.data.type, "energy": o.data.energy, "color": list(o.data.color),
                               "location": list(mw.translation),
                               "direction": list((mw.to_3x3() @ Vector((0, 0, -1))).normalized())}
    elif o.type == "CAMERA":
        d["cameras"][o.name] = {"type": o.data.type, "angle_y": o.data.angle_y, "clip_start": o.data.clip_start,
                                "clip_end": o.data.clip_end, "location": list(mw.translation),
                                "direction": list((mw.to_3x3() @ Vector((0, 0, -1))).normalized())}
for a in bpy.data.actions:
    d["actions"][a.name] = {"fcurves": len(a.fcurves), "frame_range": list(a.frame_range),
                            "bones": sorted({f.data_path.split('"')[1] for f in a.fcurves if '"' in f.data_path})}
with open(out, "w") as f:
    json.dump(d, f)
'''


def blender_import(path, tmp_path) -> dict:
    """What Blender sees after importing ``path`` (meshes, armatures, actions, lights, cameras)."""
    exe = shutil.which("blender")
    if exe is None:
        _missing("blender is not installed")
    script = tmp_path / "blender_dump.py"
    script.write_text(BLENDER_DUMP)
    out = tmp_path / "blender.json"
    r = subprocess.run([exe, "--background", "--factory-startup", "--python-exit-code", "1", "--python", str(script),
                        "--", str(path), str(out)], capture_output=True, text=True, timeout=300)
    if r.returncode != 0 or not out.exists():
        raise AssertionError(f"blender import failed ({r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
    return json.loads(out.read_text())
