"""World lighting: lights, the lighting equation, baked per-patch light maps, the PS2 blend.

Public API
----------
::

    AmbientLight, DirectionalLight, PointLight, SpotLight   light types (negative intensity darkens)
    Lights                      an ordered collection; ``load_lights(path)`` reads TOML,
                                ``default_lights()`` the default course's lights
    shade                       the lighting equation at (k, 3) points -> (k, 3) float32
    light_terms                 per-light Lambert x attenuation x cone factors, (k, m)
    atlas_layout, AtlasLayout   light-map atlas tiles (texel-centre UVs, gutters)
    with_lightmap_layout        a net whose ``lightmap_rect`` points at a layout's tiles
    sample_points               a net's light-map sample points and seam-consistent normals
    sample_atlas                point / bilinear atlas sampling (numpy, like the GPU)
    LightMap                    a baked atlas (+ rects, manifest); ``.sample``, ``.apply(net)``
    bake_lightmap               the baker (shadows, chunks, process pool, resumable; ``bounces`` for sky
                                light and inter-reflection, ``sun_radius`` for an area sun: piste.lighting.gi)
    write_lightmap, load_lightmap   the on-disk form (PNG half-bright, .npz float, manifest.json)
    load_or_bake_default_lightmap   cached bake of the default course for the renderer
    ps2_source, ps2_blend, modulate, ps2_error_report   the PS2 light-map blend trick
    VertexLights, choose_lights, vertex_light   per-vertex 1 ambient + 3 directional (characters, objects)
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562): a render imports no baker (tests/test_lazy_imports.py)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "lights": ("AmbientLight", "DirectionalLight", "PointLight", "SpotLight", "Lights", "load_lights", "loads_lights",
               "dumps_lights", "default_lights", "shade", "light_terms"),
    "lightmap": ("AtlasLayout", "atlas_layout", "with_lightmap_layout", "sample_points", "sample_atlas", "lightmap_uv",
                 "assemble_atlas", "encode_half_bright", "decode_half_bright", "LightMap"),
    "baker": ("bake_lightmap", "write_lightmap", "load_lightmap", "load_or_bake_default_lightmap"),
    "ps2": ("ps2_source", "ps2_blend", "modulate", "ps2_error_report"),
    "vertex": ("VertexLights", "choose_lights", "choose_lights_many", "vertex_light"),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.lighting.baker import bake_lightmap, load_lightmap, load_or_bake_default_lightmap, write_lightmap  # noqa: F401
    from piste.lighting.lightmap import AtlasLayout, LightMap, assemble_atlas, atlas_layout, decode_half_bright, encode_half_bright, lightmap_uv, sample_atlas, sample_points, with_lightmap_layout  # noqa: F401
    from piste.lighting.lights import AmbientLight, DirectionalLight, Lights, PointLight, SpotLight, default_lights, dumps_lights, light_terms, load_lights, loads_lights, shade  # noqa: F401
    from piste.lighting.ps2 import modulate, ps2_blend, ps2_error_report, ps2_source  # noqa: F401
    from piste.lighting.vertex import VertexLights, choose_lights, choose_lights_many, vertex_light  # noqa: F401
