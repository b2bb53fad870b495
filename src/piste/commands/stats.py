"""``piste stats [NET] [--eye X Y Z] [--target X Y Z]``: the talk's terrain statistics table."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

    import numpy as np

    from piste.terrain.net import PatchNet


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("net", nargs="?", help="a .bpt or .npz patch net (default: the default course)")
    parser.add_argument("--eye", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"), help="camera position")
    parser.add_argument("--target", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"), help="camera target")
    parser.add_argument("--near", type=N.real(0.0, N.MAX_COORDINATE, lo_open=True), default=None,
                        help="edges nearer than this get 8 vertices")
    parser.add_argument("--far", type=N.real(0.0, N.MAX_COORDINATE, lo_open=True), default=None,
                        help="edges nearer than this get 6 vertices")
    parser.add_argument("--no-cull", action="store_true", help="count every patch, not just the visible ones")
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")


def default_camera(net: PatchNet, is_course: bool) -> tuple[np.ndarray, np.ndarray]:
    """Eye and target: a rider's view down the track on the default course, else an oblique view."""
    import numpy as np

    from piste.terrain.stats import default_view

    if is_course:
        from piste.world.course import track_centerline

        track = track_centerline()
        i = len(track) // 5
        eye = track[i] + np.array([0.0, 0.0, 4.0])
        return eye, track[min(i + len(track) // 20, len(track) - 1)]
    return default_view(net)


def run(args: argparse.Namespace) -> int:
    import json

    from piste.pipeline.open_scene import load_net
    from piste.terrain import format_stats, stats
    from piste.terrain.lod import DEFAULT_FAR, DEFAULT_NEAR

    net = load_net(args.net)
    eye, target = default_camera(net, args.net is None)
    eye = args.eye if args.eye is not None else eye
    target = args.target if args.target is not None else target
    s = stats(net, eye, target, near=args.near if args.near is not None else DEFAULT_NEAR,
              far=args.far if args.far is not None else DEFAULT_FAR, cull=not args.no_cull)
    if args.json:
        print(json.dumps(s, indent=2))
    else:
        print(f"net: {net.name} ({len(net)} patches)  eye {[round(x, 1) for x in s['eye']]}  "
              f"target {[round(x, 1) for x in s['target']]}")
        print(format_stats(s))
    return 0
