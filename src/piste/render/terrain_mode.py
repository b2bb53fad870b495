"""How one scene frame draws its terrain: the strategy :class:`~piste.render.scene_renderer.SceneRenderer`
follows (``terrain.frame_mode(lightmap_mode, debug)``), so that the renderer keeps no branch per
light-map mode or terrain kind.

API
---
::

    TerrainMode(terrain, lightmap_mode="modulate", debug=None)   .prepare(camera, lod, timings) -> mesh
                                                                 .draw(camera, mesh, fog, timings) -> Frame
                                                                 .fog: riders and objects are fogged too
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from piste.world.camera import Camera

__all__ = ["TerrainMode"]


class TerrainMode:
    """How one scene frame draws its terrain: the strategy :class:`piste.render.scene_renderer.SceneRenderer`
    follows, so that it keeps no per-mode branches.  This one is the terrain renderer's own pass in
    ``lightmap_mode`` (any terrain renderer: :class:`~piste.render.frame.TerrainRenderer`, an SSX
    level's in modes other than ``ps2``, a tiled world's
    :class:`~piste.render.streaming.StreamingTerrain`).  Each terrain renderer's
    ``frame_mode(lightmap_mode, debug)`` says which mode a frame uses: an SSX level's ``ps2`` frame
    is :class:`piste.render.ssx_pass.SourceMode`."""

    #: riders and objects are fogged like the terrain (the SSX ps2 frame has no fog)
    fog = True

    def __init__(self, terrain: Any, lightmap_mode: str = "modulate", debug: str | None = None) -> None:
        # terrain: any terrain renderer (frame.TerrainRenderer, ssx_pass.SsxTerrainRenderer, streaming.StreamingTerrain)
        self.terrain = terrain
        self.lightmap_mode = lightmap_mode
        self.debug = debug

    def prepare(self, camera: Camera, lod: bool = True, timings: dict | None = None) -> Any:
        """The frame's terrain mesh for ``camera`` (LOD, culling, tessellation: no GL call)."""
        return self.terrain.prepare(camera, lod=lod, levels=None, timings=timings)

    def draw(self, camera: Camera, mesh: Any, fog: Any = None, timings: dict | None = None) -> Any:
        """Draw ``mesh`` (+ sky) into the terrain's target without waiting for the GL or reading
        back (the scene's passes follow); returns the terrain's :class:`~piste.render.frame.Frame`
        (typed Any: piste.render.frame imports this module)."""
        return self.terrain.draw(camera, mesh, lightmap_mode=self.lightmap_mode, fog=fog, read=False,
                                 timings=timings, debug=self.debug, sync=False)
