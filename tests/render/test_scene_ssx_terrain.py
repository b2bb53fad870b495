"""An SSX level with riders: :class:`~piste.render.scene_renderer.SceneRenderer` draws the terrain
with the level's :class:`~piste.render.ssx_pass.SsxTerrainRenderer` (``terrain=``), so ``ps2`` mode
blends the stored Cs/As with riders on screen too, as the terrain-only preview does."""

from __future__ import annotations

import numpy as np

from piste.pipeline.ssx_synth import make_level
from piste.pipeline import load_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.preview import ScenePreview
from piste.pipeline.ssx_level import load_level
from piste.render.ssx_pass import SsxTerrainRenderer


def test_riders_on_an_ssx_level_keep_the_stored_light_maps(tmp_path, gl):
    make_level(rows=2, cols=3, seed=2).write(tmp_path, "LV")
    lo, hi = load_level(tmp_path / "LV.pbd").net.bounds
    cx, cy = (np.asarray(lo[:2]) + np.asarray(hi[:2])) / 2
    scene = tmp_path / "s.toml"
    scene.write_text(f'terrain = {{ ssx_pbd = "LV.pbd" }}\n[render]\nsize = [96, 64]\nlightmap_mode = "ps2"\n'
                     f'[[riders]]\nposition = [{cx}, {cy}]\n'
                     f'[[cameras]]\nname = "c"\neye = [{cx}, {cy - 9}, 10.0]\ntarget = [{cx}, {cy}, 3.0]\n')
    b = load_bundle(build_scene(scene, use_cache=False).path)
    p = ScenePreview(b, ctx=gl, shadows=False)
    try:
        assert p.renderer is not None and isinstance(p.renderer.terrain, SsxTerrainRenderer)
        with_rider = p.render().astype(int)
    finally:
        p.release()
    t = ScenePreview(b, ctx=gl, terrain_only=True)
    try:
        terrain = t.render().astype(int)
    finally:
        t.release()
    d = np.abs(with_rider - terrain).max(-1)
    assert (d > 30).sum() >= 5  # the rider is drawn
    assert np.median(d) == 0 and d.mean() < 0.6  # the rest is the level's own ps2 blend (generic shader: ~1.1)


def test_frame_mode_is_the_only_place_that_knows_the_ssx_ps2_frame(tmp_path, gl):
    """SceneRenderer follows its terrain renderer's TerrainMode (``frame_mode``): an SSX level's ps2
    frame (base texture + stored texels, explicit levels, no fog) is SourceMode, every other frame
    the terrain renderer's own pass; SceneRenderer itself has no ps2 branch."""
    import ast
    import inspect

    from piste.render import scene_renderer
    from piste.render.frame import TerrainRenderer
    from piste.render.ssx_pass import SourceMode
    from piste.render.terrain_mode import TerrainMode

    make_level(rows=1, cols=2, seed=3).write(tmp_path, "LV")
    lv = load_level(tmp_path / "LV.pbd")
    ssx = SsxTerrainRenderer(lv.net, lv.source, size=(32, 24), ctx=gl)
    plain = TerrainRenderer(lv.net, size=(32, 24), ctx=gl)
    try:
        m = ssx.frame_mode("ps2")
        assert type(m) is SourceMode and m.fog is False
        for terrain, mode, debug in ((ssx, "ps2", "lod"), (ssx, "modulate", None), (plain, "ps2", None)):
            m = terrain.frame_mode(mode, debug)
            assert type(m) is TerrainMode and m.fog is True and (m.lightmap_mode, m.debug) == (mode, debug)
    finally:
        ssx.release()
        plain.release()
    tree = ast.parse(inspect.getsource(scene_renderer.SceneRenderer))
    ps2 = [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Constant) and n.value == "ps2"]
    assert ps2 == [], f"SceneRenderer compares with 'ps2' at its lines {ps2}: that belongs in a TerrainMode"
    assert "ssx_source" not in inspect.getsource(scene_renderer.SceneRenderer).split('"""', 2)[2]
