"""A glTF rider's material in the character pass: alphaMode MASK discards the cut-out texels,
a single-sided material culls back faces, a double-sided one draws them; no material (the
built-in and SSX riders) draws everything as before."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from piste.character import SkinnedMesh
from piste.formats.gltf_ext import MaterialInfo
from piste.lighting.vertex import VertexLights
from piste.render.character_pass import CharacterPass
from piste.render.context import Offscreen
from piste.world.camera import Camera

SIZE = (96, 48)


def _mesh():
    """Three quads in the z = 0 plane seen from +z: 0 front-facing on the opaque red texels, 1
    front-facing on the cut-out green ones (alpha 0), 2 back-facing (clockwise) on red."""
    pos, tri, uv = [], [], []
    for i, (u, back) in enumerate(((0.25, False), (0.75, False), (0.25, True))):
        x = 1.2 * i
        pos += [(x, 0, 0), (x + 1, 0, 0), (x + 1, 1, 0), (x, 1, 0)]
        t = [(4 * i, 4 * i + 1, 4 * i + 2), (4 * i, 4 * i + 2, 4 * i + 3)]
        tri += [tuple(reversed(a)) for a in t] if back else t
        uv += [(u, 0.5)] * 4
    return SkinnedMesh("quads", np.array(pos, float), tri, normals=np.tile([0.0, 0, 1], (12, 1)), uv=np.array(uv))


def _draw(gl, material):
    mesh = _mesh()
    tex = np.zeros((4, 8, 4), np.uint8)
    tex[:, :4] = (255, 0, 0, 255)
    tex[:, 4:] = (0, 255, 0, 0)
    cp = CharacterPass(gl, [SimpleNamespace(mesh=mesh)], tex, max_riders=1, rider_atlas=False, material=material)
    target = Offscreen(gl, SIZE)
    cam = Camera(np.array([1.7, 0.5, 4.0]), np.array([1.7, 0.51, 0.0]), fov_y=60, aspect=SIZE[0] / SIZE[1])
    vl = VertexLights(np.zeros((1, 3, 3), np.float32), np.zeros((1, 3, 3), np.float32), np.ones((1, 3), np.float32))
    try:
        cp.upload([(np.array([0]), mesh.positions[None], mesh.normals[None])])
        target.use()
        target.clear((0, 0, 1, 1))
        cp.draw(cam.view_projection(), cam.eye, vl)
        img = target.read()[..., :3].astype(int)
    finally:
        cp.release()
        target.release()
    vp = cam.view_projection()
    out = []
    for i in range(3):  # colour at each quad's centre
        p = vp @ [1.2 * i + 0.5, 0.5, 0.0, 1.0]
        x = int((p[0] / p[3] + 1) / 2 * SIZE[0])
        y = int((1 - p[1] / p[3]) / 2 * SIZE[1])
        out.append(tuple(img[y, x]))
    return out


RED, GREEN, BG = (255, 0, 0), (0, 255, 0), (0, 0, 255)


@pytest.mark.parametrize("material, want", [
    (None, [RED, GREEN, RED]),  # the built-in riders: no alpha test, no culling (unchanged)
    (MaterialInfo(), [RED, GREEN, BG]),  # OPAQUE single-sided: back faces culled
    (MaterialInfo(alpha_mode="MASK"), [RED, BG, BG]),
    (MaterialInfo(alpha_mode="MASK", double_sided=True), [RED, BG, RED]),
    (MaterialInfo(double_sided=True), [RED, GREEN, RED]),
])
def test_rider_material_alpha_mask_and_double_sided(gl, material, want):
    got = _draw(gl, material)
    np.testing.assert_allclose(np.array(got), np.array(want), atol=3)
