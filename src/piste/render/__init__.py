"""The headless OpenGL renderer (moderngl; EGL on Mesa llvmpipe without a GPU).

Public API
----------
::

    create_context        a headless moderngl context (RenderError naming the packages if impossible)
    Offscreen             RGBA8 + depth framebuffer with ``read() -> (H, W, 4) uint8``
    save_png              atomic PNG writer
    set_depth_write       depth writes on/off for the bound framebuffer (moderngl's ``ctx.depth_mask`` is no GL state)
    TerrainRenderer       camera -> LOD -> cull -> tessellate -> upload -> draw -> read back
    SceneRenderer         the completed scene: terrain + rider shadows + objects + riders + specular
                          (passes in character_pass, object_pass, shadow_pass; ``summarize_scene``)
    Frame, summarize      one frame's image, counts and timings; the talk's statistics over frames
    TerrainPass           the terrain draw: base texture x light map, ``modulate`` or ``ps2`` passes
    SkyPass               gradient sky
    cull_boxes            vectorised frustum culling of boxes (centre +- half extents)
    VideoWriter           atomic H.264 MP4 output (imageio-ffmpeg)
    snow_texture          procedural tileable snow base texture
    placeholder_lightmap  PLACEHOLDER light-map atlas from the normals and a fixed sun
    track_field           signed distance across a track on a world x-y grid (projected texture)
    mip_chain, mipmapped_texture, MipLevels
                          mip levels computed on the CPU and uploaded / redrawn by piste's shader
                          (no ``glGenerateMipmap``: Mesa compiles its blit in every process)
    LOD_COLORS            debug colours of 4x4 / 6x6 / 8x8 / glue patches
    StreamingRenderer     a tiled world paged in and out by distance under a memory budget (streaming.py)

Interactive window: :func:`piste.render.window.run_window` (pyglet, imported lazily).
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "context": ("create_context", "Offscreen", "save_png", "set_depth_write"),
    "textures": ("mip_chain", "mipmapped_texture", "MipLevels", "track_field", "snow_texture", "placeholder_lightmap",
                 "lightmap_atlas_size", "LOD_COLORS"),
    "frame": ("TerrainRenderer", "Frame", "summarize", "cull_boxes"),
    "scene_renderer": ("SceneRenderer", "SceneImage", "summarize_scene"),
    "video": ("VideoWriter",),
    # post-processes and the occlusion pass a frame uses only when asked (a bundle render imports none)
    "dof": ("check_dof",),
    "interlace": ("weave",),
    "occlusion": ("occlude_frame",),
    "terrain_pass": ("TerrainPass", "LIGHTMAP_MODES", "DEBUG_VIEWS"),
    "sky_pass": ("SkyPass",),
    "streaming": ("StreamingRenderer", "TileCache", "render_flight", "StreamingTerrain"),
    "ssx_pass": ("SsxTerrainRenderer",),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.render.context import Offscreen, create_context, save_png, set_depth_write  # noqa: F401
    from piste.render.frame import Frame, TerrainRenderer, cull_boxes, summarize  # noqa: F401
    from piste.render.scene_renderer import SceneImage, SceneRenderer, summarize_scene  # noqa: F401
    from piste.render.sky_pass import SkyPass  # noqa: F401
    from piste.render.terrain_pass import DEBUG_VIEWS, LIGHTMAP_MODES, TerrainPass  # noqa: F401
    from piste.render.textures import LOD_COLORS, MipLevels, lightmap_atlas_size, mip_chain, mipmapped_texture, placeholder_lightmap, snow_texture, track_field  # noqa: F401
    from piste.render.video import VideoWriter  # noqa: F401
    from piste.render.dof import check_dof  # noqa: F401
    from piste.render.interlace import weave  # noqa: F401
    from piste.render.occlusion import occlude_frame  # noqa: F401
    from piste.render.streaming import StreamingRenderer, StreamingTerrain, TileCache, render_flight  # noqa: F401
    from piste.render.ssx_pass import SsxTerrainRenderer  # noqa: F401
