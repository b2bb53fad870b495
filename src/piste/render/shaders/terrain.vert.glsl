#version 330 core
// Terrain vertices: world position, base-texture UV, light-map atlas UV (and, for the LOD view,
// the patch kind: 4, 6, 8, or 0 for a glue patch).  Every terrain pass uses this shader, so the
// passes' depths are identical (``invariant``) and the PS2 second pass can test with GL_EQUAL.
//
// Geomorphing (resident terrain, u_morph_on = 1): each vertex also carries its morph target (the
// same parameter point on the next coarser level) and a morph slot; this frame's factor for the
// slot comes from u_morph (one float per slot, 1024 a row) and the drawn position is
// target + f (position - target).  Both copies of a shared edge vertex have the same inputs, so
// they land on the same bits.
//
// Per vertex too (the PS2 fogged per vertex): the fog factor v_fog (u_fog.a = density per metre,
// 0 off) and, compiled with TERRAIN_TRACK 1, the groomed track's signed distance v_track_d (metres
// across the track, looked up in the track field u_track by world x-y).  The field is a smooth
// function of x-y (a straight or gently curving centre line), close to linear across a triangle,
// so interpolating the vertices' distances gives the per-pixel look-up's dye lines within a few
// pixels' edge shading; the per-pixel look-up (a half-float bilinear fetch) cost llvmpipe's
// rasterizer threads ~0.9 ms of CPU a frame on the default course (~12 % of the terrain's fill).
uniform mat4 u_mvp;
uniform vec3 u_eye;
uniform vec4 u_fog;
uniform vec4 u_track_rect;   // x0, y0, 1/width, 1/height of the track field in metres
uniform float u_depth_bias;  // clip-space z offset, a fraction of w (wireframe overlay)
uniform int u_morph_on;
uniform sampler2D u_morph;
uniform sampler2D u_track;   // signed distance across the track, metres (TERRAIN_TRACK 1)
in vec3 in_pos;
in vec3 in_target;
in float in_morph;
in vec2 in_uv;
in vec2 in_uvl;
in float in_kind;
out vec2 v_uv;
out vec2 v_uvl;
out vec3 v_world;
out float v_track_d;
out float v_fog;
flat out float v_kind;
invariant gl_Position;
void main() {
    vec3 p = in_pos;
    if (u_morph_on == 1) {
        int id = int(in_morph);
        float f = texelFetch(u_morph, ivec2(id & 1023, id >> 10), 0).r;
        p = in_target + f * (in_pos - in_target);
    }
    gl_Position = u_mvp * vec4(p, 1.0);
    gl_Position.z -= u_depth_bias * gl_Position.w;
    v_uv = in_uv;
    v_uvl = in_uvl;
    v_world = p;
#if defined(TERRAIN_TRACK) && TERRAIN_TRACK == 1
    v_track_d = textureLod(u_track, (p.xy - u_track_rect.xy) * u_track_rect.zw, 0.0).r;
#else
    v_track_d = 0.0;
#endif
    v_fog = u_fog.a > 0.0 ? 1.0 - exp(-u_fog.a * distance(p, u_eye)) : 0.0;
    v_kind = in_kind;
}
