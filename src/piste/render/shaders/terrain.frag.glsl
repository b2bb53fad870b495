#version 330 core
// The terrain's first pass, compiled once per mode (TERRAIN_MODE is defined by the renderer: a
// run-time if-chain on a uniform costs llvmpipe about 40 % of the draw).  Mode: 0 modulate (Cd x CL, what modern GPUs do), 1 base texture
// only (Cd, the first pass of the PS2 scheme), 2 light map only (CL), 3 LOD colours, 4 flat colour
// (wireframe lines), 5 LOD colours darkened (the LOD view's wireframe).  Fog (u_fog.a = density per metre) mixes towards the horizon colour.
#include "base_color.glsl"
uniform sampler2D u_light;
#ifndef TERRAIN_MODE
#define TERRAIN_MODE 0
#endif
const int u_mode = TERRAIN_MODE;
uniform vec4 u_fog;
uniform vec3 u_color;
uniform vec3 u_lod_colors[4];  // glue, 4x4, 6x6, 8x8
in vec2 v_uv;
in vec2 v_uvl;
in float v_track_d;
in float v_fog;
flat in float v_kind;
out vec4 f_color;
void main() {
    vec3 c;
    if (u_mode == 0) {
        c = base_color(v_uv, v_track_d) * texture(u_light, v_uvl).rgb;
    } else if (u_mode == 1) {
        c = base_color(v_uv, v_track_d);
    } else if (u_mode == 2) {
        c = texture(u_light, v_uvl).rgb;
    } else if (u_mode == 3 || u_mode == 5) {
        int k = int(v_kind + 0.5);
        // (flat patches, 2 vertices a side, in the coarsest level's colour)
        vec3 lod = (k == 4 || k == 2) ? u_lod_colors[1] : k == 6 ? u_lod_colors[2] : k == 8 ? u_lod_colors[3]
                 : u_lod_colors[0];
        // mode 5: the wireframe over the LOD view, a darker shade of the patch's colour (so that
        // dense far-away lines still show the colour)
        c = u_mode == 5 ? lod * 0.35 : lod * (0.35 + 0.65 * texture(u_light, v_uvl).rgb);
    } else {
        c = u_color;
    }
    if (u_fog.a > 0.0 && u_mode < 4) {
        c = mix(c, u_fog.rgb, v_fog);  // the factor per vertex
    }
    f_color = vec4(c, 1.0);
}
