"""Small nets and lights for the lighting tests (deterministic, fast)."""

from __future__ import annotations

import numpy as np

from piste.lighting import AmbientLight, DirectionalLight, Lights, PointLight, SpotLight
from piste.terrain import PatchNet


def hill_net(nx: int = 3, ny: int = 3, size: float = 10.0, relief: float = 3.0, crease: float = 0.0) -> PatchNet:
    """A C0 height-field net of ``nx x ny`` patches over ``[0, nx size] x [0, ny size]``, Z up.

    ``crease`` adds a slope jump across every patch boundary (C0 but not C1), like a C0 fit.
    """
    gx = np.linspace(0.0, nx * size, 3 * nx + 1)
    gy = np.linspace(0.0, ny * size, 3 * ny + 1)
    y, x = np.meshgrid(gy, gx, indexing="ij")
    sx, sy = x / (nx * size), y / (ny * size)
    z = relief * (np.sin(np.pi * sx) * np.sin(np.pi * sy) + 0.3 * np.cos(3.0 * np.pi * sx) * np.sin(2.0 * np.pi * sy))
    if crease:
        # inner control rows/cols get an alternating offset: the tangent jumps across each edge
        k = np.arange(3 * nx + 1) % 3
        z = z + crease * (k[None, :] == 1) - crease * (k[None, :] == 2)
    return PatchNet.from_control_grid(np.stack([x, y, z], -1), name="hill")


def wall_scene() -> PatchNet:
    """Flat ground ``[0, 40]^2`` at z = 0 (4 x 4 patches) and a vertical wall patch standing at
    x = 20 from y = 10 to 30, z = 0 to 10, facing +x."""
    g = np.linspace(0.0, 40.0, 13)
    y, x = np.meshgrid(g, g, indexing="ij")
    ground = PatchNet.from_control_grid(np.stack([x, y, np.zeros_like(x)], -1)).control_points
    t = np.linspace(0.0, 1.0, 4)
    # wall: u along z, v along y, so du x dv = (0, 0, 1) x (0, 1, 0) = -x ... use u along y, v along z
    wy, wz = np.meshgrid(10.0 + 20.0 * t, 10.0 * t, indexing="ij")  # [i (u), j (v)]
    wall = np.stack([np.full_like(wy, 20.0), wy, wz], -1)  # du = +y, dv = +z: normal +x
    return PatchNet(np.concatenate([ground, wall[None]], 0), name="wall scene")


def make_lights() -> Lights:
    return Lights(
        (
            AmbientLight((0.3, 0.35, 0.45), 0.8, name="sky"),
            DirectionalLight((0.4, 0.3, -0.8), (1.0, 0.9, 0.75), 1.0, name="sun"),
            PointLight((15.0, 15.0, 6.0), (1.0, 0.5, 0.2), 1.5, range=14.0, falloff=2.0, name="lamp"),
            SpotLight((5.0, 25.0, 8.0), (0.3, -0.2, -1.0), (0.2, 1.0, 0.4), 1.0, range=20.0, inner_angle=10.0,
                      outer_angle=25.0, name="spot"),
            PointLight((22.0, 8.0, 2.5), (1.0, 1.0, 1.0), -0.7, range=6.0, falloff=1.0, shadows=False, name="hollow"),
        ),
        name="test",
    )


def shuffle_orientation(net: PatchNet, seed: int = 0) -> PatchNet:
    """The same surface with some patches' parameter directions reversed or swapped, so shared
    edges are traversed both ways (``side_flip``) and tiles meet in every orientation."""
    rng = np.random.default_rng(seed)
    cp = net.control_points.copy()
    kind = rng.integers(0, 4, len(cp))
    cp[kind == 1] = cp[kind == 1][:, ::-1, ::-1]  # reverse u and v (keeps the normal side)
    cp[kind == 2] = cp[kind == 2][:, ::-1].transpose(0, 2, 1, 3)  # rotate the parameter square
    cp[kind == 3] = cp[kind == 3][:, :, ::-1].transpose(0, 2, 1, 3)
    return PatchNet(cp, name=net.name)
