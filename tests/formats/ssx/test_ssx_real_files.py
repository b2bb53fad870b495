"""Optional: the user's own extracted SSX Tricky level files (never in the repo).

Set ``PISTE_SSX_TRICKY_DIR`` to a folder holding extracted level files (``<NAME>.pbd`` with
``<NAME>.ssh`` and ``<NAME>_L.ssh`` beside them, as the game's BIG archives hold them; any other
``.ssh`` banks too).  Every ``.pbd`` and ``.ssh`` found below it (recursively) must open and be
written back byte for byte, and every level must pass through a Multitool project the Multitool's
way (issue 22 items 3, 7).  Skipped when the variable is unset; each test skips when the folder
holds none of its kind (the variable may point at a folder of ``.mpf`` models only).  Run with
``-s`` to see the counts.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.ssx import lightmap_pages, parse_pbd, parse_ssh, read_pbd, read_ssh
from piste.formats.ssx.multitool import brighten, darken, export_lightmap, read_project, write_project
from piste.formats.ssx.pbd import PLATFORMS
from piste.pipeline.ssx_level import level_files
from piste.pipeline.ssx_level import pbd_to_net

ROOT = os.environ.get("PISTE_SSX_TRICKY_DIR")
pytestmark = pytest.mark.skipif(not ROOT, reason="PISTE_SSX_TRICKY_DIR is not set (point it at your own extracted "
                                                  "SSX Tricky level files to run this test)")


def _found(suffix: str) -> list:
    files = sorted(p for p in Path(ROOT).rglob("*") if p.is_file() and p.suffix.lower() == suffix)
    if not files:
        pytest.skip(f"PISTE_SSX_TRICKY_DIR={ROOT}: no {suffix} files below it")
    return files


def test_every_pbd_opens_and_writes_back_byte_identical():
    files = _found(".pbd")
    welded = 0
    for path in files:
        pbd = read_pbd(path)
        assert pbd.to_bytes() == pbd.raw, f"{path}: not written back byte for byte"
        assert pbd.platform in PLATFORMS
        if pbd.n_patches == 0:
            continue
        # an edited patch re-encodes within float32 of the edit, the rest stays bit-identical
        q = parse_pbd(pbd.raw, path)
        q.control_points[0, 1, 1, 2] += 10.0
        r = parse_pbd(q.to_bytes(), path)
        np.testing.assert_allclose(r.control_points[0], q.control_points[0], atol=0.5)
        np.testing.assert_array_equal(r.records["power"][1:], pbd.records["power"][1:])
        if pbd.n_patches > 1:
            net = pbd_to_net(pbd)
            assert len(net.shared_edges) > 0.5 * len(net), f"{path.name}: few seams welded"
            welded += 1
    print(f"\n{len(files)} .pbd files opened and written back byte-identical ({welded} welded)")


def test_every_ssh_opens_and_writes_back_byte_identical():
    files = _found(".ssh")
    opened, same_layout, kept, refused = 0, 0, 0, []
    for path in files:
        try:
            bank = read_ssh(path)
        except FormatError as exc:  # allowed only with the "not supported yet" message
            assert "not supported yet" in str(exc), str(exc)
            refused.append(f"{path.name}: {exc}")
            continue
        opened += 1
        raw = path.read_bytes()
        assert bank.to_bytes() == raw, f"{path}: not written back byte for byte"
        # piste's own layout holds the same images (and is the game's layout when equal)
        again = parse_ssh(bank.encode(), path)
        assert len(again) == len(bank)
        for a, b in zip(bank.images, again.images):
            assert (a.name, a.kind, a.long_name, a.extra) == (b.name, b.kind, b.long_name, b.extra), path
            np.testing.assert_array_equal(a.stored_rgba(), b.stored_rgba())
        same_layout += bank.encode() == raw
        kept += sum(len(im.extra) for im in bank.images)
    print(f"\n{len(files)} .ssh banks: {opened} opened and written back byte-identical ({same_layout} also in "
          f"piste's own layout, {kept} hot-spot/metal-alpha chunks kept), {len(refused)} refused as not "
          "supported yet" + "".join(f"\n  {r}" for r in refused))
    assert opened > 0


def _multitool_read_pages(folder: Path) -> np.ndarray:
    """The Multitool's import of Lightmaps/*.png (name order, RGB (c + 1) // 2, alpha as is)."""
    from PIL import Image

    files = sorted((folder / "Lightmaps").glob("*.png"), key=lambda p: p.name)
    pages = [np.asarray(Image.open(f).convert("RGBA")) for f in files]
    out = np.stack(pages).copy()
    out[..., :3] = darken(out[..., :3])
    return out


def test_levels_pass_through_the_multitool_conventions(tmp_path):
    files = [p for p in _found(".pbd") if read_pbd(p).n_patches > 0]
    done, texels, lossy = 0, 0, 0
    for path in files:
        ssh, lssh = level_files(path)
        if ssh is None or lssh is None:
            continue
        try:
            pbd, textures, lightmaps = read_pbd(path), read_ssh(ssh), read_ssh(lssh)
        except FormatError as exc:
            assert "not supported yet" in str(exc), str(exc)
            continue
        pages = lightmap_pages(lightmaps, lssh)
        proj = tmp_path / path.stem
        write_project(proj, pbd, textures, lightmaps)
        # the PNGs are the Multitool's export: brightened RGB, alpha as stored
        mt = _multitool_read_pages(proj)
        np.testing.assert_array_equal(mt[..., 3], pages[..., 3])
        exact = pages[..., :3] <= 128  # brighten/darken are exact inverses up to 128
        np.testing.assert_array_equal(mt[..., :3][exact], pages[..., :3][exact])
        np.testing.assert_array_equal(mt[..., :3][~exact], 128)
        np.testing.assert_array_equal(export_lightmap(pages[0])[..., :3], brighten(pages[0, ..., :3]))
        texels += exact.size
        lossy += int((~exact).sum())
        # read back by piste: the same .pbd, the same light-map texels (up to 128), the textures' RGB
        new_pbd, new_tex, new_lms = read_project(proj).to_level()
        assert new_pbd.to_bytes() == pbd.raw, f"{path.name}: the round trip changed the .pbd"
        back = lightmap_pages(new_lms)
        np.testing.assert_array_equal(back[..., 3], pages[..., 3])
        np.testing.assert_array_equal(back[..., :3][exact], pages[..., :3][exact])
        if len(new_tex) == len(textures):  # same numbering when every texture is referenced
            for a, b in zip(new_tex.images, textures.images):
                sa, sb = a.stored_rgba()[..., :3], b.stored_rgba()[..., :3]
                ok = sb <= 128
                np.testing.assert_array_equal(sa[ok], sb[ok])
        done += 1
    if not done:
        pytest.skip("no level with its .ssh and _L.ssh beside it")
    print(f"\n{done} levels through a Multitool project and back: .pbd byte-identical; light-map texels "
          f"{texels - lossy} of {texels} exact, {lossy} above 128 (the Multitool's brightening clamps them)")
