"""Every terrain source of a scene: .bpt (any net, rays visibility), a saved net, PNG and .npz height fields."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.build import build_scene

TEAPOT = Path(__file__).resolve().parents[3] / "shared" / "data" / "patches" / "teapot.bpt"


def test_bpt_terrain_uses_exact_ray_visibility(tmp_path):
    from piste.formats.bpt import write_bpt
    from piste.terrain.net import PatchNet

    if TEAPOT.exists():
        cp = PatchNet.from_bpt(TEAPOT).control_points
    else:  # pragma: no cover - a folded sheet stands in
        g = np.zeros((4, 7, 3))
        g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(4.0))
        g[:, 3:, 2] = 2.0
        cp = PatchNet.from_control_grid(g).control_points
    write_bpt(tmp_path / "t.bpt", cp)
    (tmp_path / "t.toml").write_text('[terrain]\nsource = "t.bpt"\n[lightmap]\nres = 4\n[visibility]\ncell = 2.0\n'
                                     'eye_heights = [0.5]\n')
    r = build_scene(tmp_path / "t.toml")
    b = load_bundle(r.path)
    assert b.visibility.method == "rays"
    assert list(b.cameras) == ["overview"]  # no cameras given: one framing the whole net
    assert np.array_equal(b.net.control_points, PatchNet(cp).control_points)


def test_saved_net_and_heightfields(tmp_path):
    from PIL import Image

    from piste.terrain.fit import fit_heightfield

    y, x = np.mgrid[0:17, 0:17]
    z = 10.0 + 0.5 * x + 0.2 * y
    fit_heightfield(z, 2.0).save(tmp_path / "net.npz")
    Image.fromarray(np.rint(z * 100).astype(np.uint16)).save(tmp_path / "h.png")
    np.savez(tmp_path / "h.npz", elevation=z, spacing=np.array([2.0, 2.0]))
    scenes = {
        "net": '[terrain]\nsource = "net.npz"\n',
        "png": '[terrain]\nsource = "h.png"\nspacing = 2.0\nheight_scale = 0.01\n',
        "npz": '[terrain]\nsource = "h.npz"\nkey = "elevation"\n',
    }
    nets = {}
    for name, text in scenes.items():
        (tmp_path / f"{name}.toml").write_text(text + "[lightmap]\nres = 4\n[visibility]\ncell = 16.0\n")
        b = load_bundle(build_scene(tmp_path / f"{name}.toml").path)
        nets[name] = b.net.control_points
        assert b.manifest["terrain"]["kind"] == ("net" if name == "net" else "heightfield")
    # a 16-bit PNG at 0.01 m a level holds these heights exactly: the same fit as the arrays
    assert np.allclose(nets["png"], nets["npz"], atol=1e-9)
    assert np.allclose(nets["net"], nets["npz"], atol=1e-9)


def test_heightfield_npz_without_spacing_is_an_error(tmp_path):
    from piste.errors import FormatError

    np.savez(tmp_path / "h.npz", z=np.zeros((9, 9)))
    (tmp_path / "s.toml").write_text('[terrain]\nsource = "h.npz"\n')
    with pytest.raises(FormatError, match="spacing"):
        build_scene(tmp_path / "s.toml")
