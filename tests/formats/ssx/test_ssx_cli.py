"""The CLI on a synthetic level: piste ssx make/info/render/convert, piste render/view/bake LEVEL.pbd."""

from __future__ import annotations

import numpy as np
import pytest

from piste.cli import main
from piste.formats.ssx import read_pbd, read_ssh
from piste.terrain.net import PatchNet
from piste.pipeline.ssx_level import pbd_to_net


def test_cli_end_to_end(tmp_path, capsys, monkeypatch, gl):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["ssx", "make", str(tmp_path), "--rows", "2", "--cols", "2", "--name", "LV"]) == 0
    lv = tmp_path / "LV.pbd"
    assert main(["ssx", "info", str(lv)]) == 0
    assert "4 patches" in capsys.readouterr().out
    assert main(["render", str(lv), "--out", str(tmp_path / "r.png"), "--size", "64", "48"]) == 0
    assert main(["ssx", "render", str(lv), "--lightmap", "ps2", "--out", str(tmp_path / "p.png"),
                 "--size", "64", "48"]) == 0
    assert main(["view", str(lv), "--out", str(tmp_path / "v.png"), "--size", "64", "48"]) == 0
    from PIL import Image

    for name in ("r.png", "p.png", "v.png"):
        assert Image.open(tmp_path / name).size == (64, 48)
    # bake the game's way into a new level beside it
    out = tmp_path / "BAKED.pbd"
    assert main(["bake", str(lv), "--format", "ssx-tricky", "--out", str(out), "--jobs", "1", "--quiet"]) == 0
    assert read_pbd(out).n_patches == 4 and len(read_ssh(tmp_path / "BAKED_L.ssh")) == 1
    assert main(["ssx", "convert", str(lv), "--to", "npz", "--out", str(tmp_path / "lv.npz")]) == 0
    net = PatchNet.load(tmp_path / "lv.npz")
    np.testing.assert_allclose(net.control_points, pbd_to_net(read_pbd(lv)).control_points)
    # and any piste net back into a level
    assert main(["ssx", "make", str(tmp_path / "fromnet"), "--from", str(tmp_path / "lv.npz"), "--name", "N"]) == 0
    np.testing.assert_allclose(pbd_to_net(read_pbd(tmp_path / "fromnet" / "N.pbd")).control_points, net.control_points,
                               atol=1e-4)
    assert main(["ssx", "convert", str(lv), "--to", "multitool", "--out", str(tmp_path / "proj")]) == 0
    assert (tmp_path / "proj" / "Patches.json").is_file()
    assert main(["ssx", "import", str(tmp_path / "proj"), "--out", str(tmp_path / "back" / "LV2.pbd")]) == 0
    back = read_pbd(tmp_path / "back" / "LV2.pbd")
    np.testing.assert_allclose(back.control_points, read_pbd(lv).control_points, atol=0.05)
    assert len(read_ssh(tmp_path / "back" / "LV2.ssh")) == 3 and len(read_ssh(tmp_path / "back" / "LV2_L.ssh")) == 1
    assert main(["ssx", "convert", str(lv), "--to", "gltf", "--out", str(tmp_path / "lv.glb")]) == 0
    import pygltflib

    g = pygltflib.GLTF2().load(str(tmp_path / "lv.glb"))
    assert len(g.images) == 2 and len(g.meshes) >= 1  # the level's texture atlas and its light map
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".toml", ".piste")) == []


def test_cli_bad_level(tmp_path, capsys):
    bad = tmp_path / "BAD.pbd"
    bad.write_bytes(b"\x00\x15\x1b\x07" + bytes(200))
    assert main(["ssx", "info", str(bad)]) != 0
    err = capsys.readouterr().err
    assert "BAD.pbd" in err and "platform" in err and "Traceback" not in err


def _need(tool: str, package: str):
    """Skip without ``tool``; fail instead when PISTE_REQUIRE_TOOLS is set (CI)."""
    import os
    import shutil

    if shutil.which(tool) is None:
        msg = f"{tool} not installed (apt-get install {package}; tools/setup-test-tools.sh)"
        if os.environ.get("PISTE_REQUIRE_TOOLS"):
            pytest.fail(msg)
        pytest.skip(msg)


@pytest.mark.slow
def test_view_window_under_xvfb(tmp_path, gl_context):
    """`piste view LEVEL.pbd` opens a window (Xvfb) and draws the level in ps2 mode."""
    import os
    import subprocess
    import sys

    from PIL import Image

    _need("xvfb-run", "xvfb")
    pytest.importorskip("pyglet")
    assert main(["ssx", "make", str(tmp_path), "--name", "LV"]) == 0
    shot = tmp_path / "shot.png"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run(["xvfb-run", "-a", sys.executable, "-m", "piste.cli", "view", str(tmp_path / "LV.pbd"),
                        "--frames", "3", "--lightmap", "ps2", "--size", "160", "112", "--out", str(shot)],
                       env=env, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert img.shape == (112, 160, 3)
    # the rock texture's dark brown shows below the overlay
    lower = img[70:]
    assert ((lower[..., 0] < 140) & (lower[..., 2] < lower[..., 0]) & (lower[..., 0] > 30)).mean() > 0.03
    # `piste ssx view` opens the same runtime's window (PreviewView) and draws the same level
    shot2 = tmp_path / "shot_ssx.png"
    r = subprocess.run(["xvfb-run", "-a", sys.executable, "-m", "piste.cli", "ssx", "view", str(tmp_path / "LV.pbd"),
                        "--frames", "3", "--lightmap", "ps2", "--size", "160", "112", "--out", str(shot2)],
                       env=env, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    lower = np.asarray(Image.open(shot2).convert("RGB")).astype(int)[70:]
    assert ((lower[..., 0] < 140) & (lower[..., 2] < lower[..., 0]) & (lower[..., 0] > 30)).mean() > 0.03


def test_ssx_subcommands(tmp_path, capsys, gl):
    """`piste ssx` has subcommands like `piste mpf` (issue 25): each takes only its own flags; the
    issue's sky view renders in both light-map modes; `ssx make` twice gives identical bytes."""
    import argparse

    from piste.cli import build_parser

    def subcommands(p):
        return next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices

    names = subcommands(subcommands(build_parser())["ssx"])
    assert set(names) == {"info", "render", "view", "bake", "convert", "make", "import"}
    for k in ("a", "b"):
        assert main(["ssx", "make", str(tmp_path / k), "--rows", "1", "--cols", "2", "--name", "L"]) == 0
    for f in ("L.pbd", "L.ssh", "L_L.ssh"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    lv = str(tmp_path / "a" / "L.pbd")
    for mode in ("ps2", "modulate"):  # looking at the sky: nothing to draw but the sky
        out = tmp_path / f"sky_{mode}.png"
        assert main(["ssx", "render", lv, "--lightmap", mode, "--eye", "350", "200", "100", "--target", "350", "200",
                     "500", "--out", str(out), "--size", "64", "48"]) == 0
        from PIL import Image

        img = np.asarray(Image.open(out).convert("RGB")).astype(int)
        assert (img[..., 2] > img[..., 0]).all()  # blue sky everywhere
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:  # a flag of another subcommand is a usage error
        main(["ssx", "info", lv, "--rows", "3"])
    assert e.value.code == 2 and "unrecognized arguments: --rows" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["ssx", "convert", lv, "--out", str(tmp_path / "x.npz")])  # --to is required
    assert e.value.code == 2 and "--to" in capsys.readouterr().err


def test_ssx_render_and_view_are_the_runtimes_pictures(tmp_path, monkeypatch, capsys, gl):
    """Issue 25: `piste ssx render|view` draw through the one runtime, so their pictures are
    `piste render|view LEVEL.pbd`'s pixel for pixel (the level's camera and --eye/--target), and
    --lightmap ps2 is the runtime's ps2 picture; a file that is not a .pbd is named in a clear error."""
    from PIL import Image

    from piste.pipeline.open_scene import eye_camera, open_source
    from piste.pipeline.preview import ScenePreview

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["ssx", "make", str(tmp_path), "--rows", "2", "--cols", "3", "--name", "LV"]) == 0
    lv = str(tmp_path / "LV.pbd")
    size = ["--size", "96", "64"]

    def png(name):
        return np.asarray(Image.open(tmp_path / name).convert("RGB"))

    lo, hi = (np.asarray(v) for v in pbd_to_net(read_pbd(lv)).bounds)
    c = (lo + hi) / 2
    e = c + np.array([-10.0, -40.0, 25.0])
    eye = ["--eye", *map(str, e), "--target", *map(str, c)]
    for k, cam in enumerate(([], eye)):  # modulate: `piste render`'s picture
        assert main(["ssx", "render", lv, "--out", str(tmp_path / f"s{k}.png"), *size, *cam]) == 0
        assert main(["render", lv, "--out", str(tmp_path / f"r{k}.png"), *size, *cam]) == 0
        assert png(f"s{k}.png").std() > 5 and np.array_equal(png(f"s{k}.png"), png(f"r{k}.png")), k
    assert not np.array_equal(png("s0.png"), png("s1.png"))  # --eye/--target reach the runtime
    assert main(["ssx", "view", lv, "--out", str(tmp_path / "sv.png"), *size]) == 0
    assert main(["view", lv, "--out", str(tmp_path / "v.png"), *size]) == 0
    assert np.array_equal(png("sv.png"), png("v.png")) and np.array_equal(png("sv.png"), png("s0.png"))
    assert main(["ssx", "render", lv, "--lightmap", "ps2", "--out", str(tmp_path / "p.png"), *size, *eye]) == 0
    p = ScenePreview(open_source(lv), size=(96, 64), ctx=gl, lightmap_mode="ps2")
    try:
        want = p.render(eye_camera(e, c))
    finally:
        p.release()
    assert np.array_equal(png("p.png"), want) and not np.array_equal(png("p.png"), png("s1.png"))
    capsys.readouterr()
    (tmp_path / "x.obj").write_bytes(b"")
    assert main(["ssx", "render", str(tmp_path / "x.obj"), "--out", str(tmp_path / "x.png")]) != 0
    err = capsys.readouterr().err
    assert "x.obj" in err and "expected an SSX Tricky level (.pbd)" in err and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()
