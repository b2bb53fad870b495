"""Child process of test_fuzz_isolated: load each (kind, path) of a JSON list given on the command
line and print one JSON line per case: {"path", "result": "loaded" | "refused" | "raw", "message"}."""

from __future__ import annotations

import json
import sys
from pathlib import Path


def loader(kind):
    if kind == "gltf":
        from piste.formats import load_gltf
        return load_gltf
    if kind == "bpt":
        from piste.terrain import PatchNet
        return PatchNet.from_bpt
    if kind == "scene":
        from piste.world.scene_file import load_scene
        return load_scene
    if kind == "lights":
        from piste.lighting import load_lights
        return load_lights
    if kind == "bundle":
        from piste.pipeline.bundle_objects import load_bundle
        return load_bundle
    if kind == "heightfield":
        from piste.pipeline.sources import load_terrain
        from piste.world.scene_file import TerrainSpec
        return lambda p: load_terrain(TerrainSpec(kind="heightfield", path=p, spacing=(1.0, 1.0)))
    raise ValueError(kind)


def main() -> None:
    from piste.errors import PisteError

    for kind, path in json.loads(sys.argv[1]):
        try:
            loader(kind)(Path(path))
            out = {"path": path, "result": "loaded", "message": ""}
        except PisteError as exc:
            out = {"path": path, "result": "refused", "message": str(exc)[:300]}
        except BaseException as exc:  # noqa: BLE001 - reported to the parent, which fails
            out = {"path": path, "result": "raw", "message": f"{type(exc).__name__}: {str(exc)[:300]}"}
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
