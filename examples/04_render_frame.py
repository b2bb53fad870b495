"""Render a frame of the default course
====================================

Render one frame of the default course three ways: lit (modulate), lit with the PS2's two-pass
light-map blend, and the LOD view (patches coloured 4x4 green, 6x6 yellow, 8x8 red, glue blue).

Usage: python examples/04_render_frame.py [t]   (t: camera position along the track, 0..1)
Writes frame_modulate.png, frame_ps2.png, frame_lod.png to $PISTE_EXAMPLE_OUT or out/.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from piste.render import TerrainRenderer, save_png
from piste.world.camera import track_camera
from piste.world.course import TRACK_HALF_WIDTH, default_course, track_centerline


def main(argv: list[str]) -> int:
    t = float(argv[1]) if len(argv) > 1 else 0.25
    out = Path(os.environ.get("PISTE_EXAMPLE_OUT", "out"))
    net = default_course(seed=0)
    line = track_centerline(seed=0)
    renderer = TerrainRenderer(net, size=(320, 224), track=line, track_half_width=TRACK_HALF_WIDTH)
    camera = track_camera(line, t)
    images = {}
    for name, kw in {"modulate": {}, "ps2": {"lightmap_mode": "ps2"}, "lod": {"debug": "lod"}}.items():
        frame = renderer.render(camera, **kw)
        images[name] = frame.image
        path = save_png(out / f"frame_{name}.png", frame.image[..., :3])
        ms = frame.timings
        print(f"{path}: {frame.patches} patches, {frame.triangles} triangles "
              f"(4x4 {frame.kind_counts[4]}, 6x6 {frame.kind_counts[6]}, 8x8 {frame.kind_counts[8]}, "
              f"glue {frame.kind_counts[0]}); CPU {ms['cpu']:.1f} ms, draw {ms['draw']:.1f} ms")
    diff = np.abs(images["modulate"].astype(int) - images["ps2"].astype(int))
    print(f"modulate vs ps2: max difference {diff.max()} of 255 (the talk's identity Cd x CL = (Cd - Cs) x As)")
    renderer.release()
    return 0


if __name__ == "__main__":
    if rc := main(sys.argv):  # exit only on failure: the docs gallery runs this file in-process
        sys.exit(rc)
