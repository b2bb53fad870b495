"""The headless OpenGL renderer (moderngl; EGL on Mesa llvmpipe without a GPU).

Public API
----------
create_context        a headless moderngl context (RenderError naming the packages if impossible)
Offscreen             RGBA8 + depth framebuffer with ``read() -> (H, W, 4) uint8``
save_png              atomic PNG writer
TerrainRenderer       camera -> LOD -> cull -> tessellate -> upload -> draw -> read back
Frame, summarize      one frame's image, counts and timings; the talk's statistics over frames
TerrainPass           the terrain draw: base texture x light map, ``modulate`` or ``ps2`` passes
SkyPass               gradient sky
snow_texture          procedural tileable snow base texture
placeholder_lightmap  PLACEHOLDER light-map atlas from the normals and a fixed sun
LOD_COLORS            debug colours of 4x4 / 6x6 / 8x8 / glue patches
"""

from piste.render.context import Offscreen, create_context, save_png
from piste.render.frame import Frame, TerrainRenderer, summarize
from piste.render.sky_pass import SkyPass
from piste.render.terrain_pass import DEBUG_VIEWS, LIGHTMAP_MODES, TerrainPass
from piste.render.textures import LOD_COLORS, lightmap_atlas_size, placeholder_lightmap, snow_texture

__all__ = [
    "create_context",
    "Offscreen",
    "save_png",
    "TerrainRenderer",
    "Frame",
    "summarize",
    "TerrainPass",
    "SkyPass",
    "LIGHTMAP_MODES",
    "DEBUG_VIEWS",
    "snow_texture",
    "placeholder_lightmap",
    "lightmap_atlas_size",
    "LOD_COLORS",
]
