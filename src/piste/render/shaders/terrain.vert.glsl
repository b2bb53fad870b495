#version 330 core
// Terrain vertices: world position, base-texture UV, light-map atlas UV (and, for the LOD view,
// the patch kind: 4, 6, 8, or 0 for a glue patch).  Every terrain pass uses this shader, so the
// passes' depths are identical (``invariant``) and the PS2 second pass can test with GL_EQUAL.
uniform mat4 u_mvp;
uniform float u_depth_bias;  // clip-space z offset, a fraction of w (wireframe overlay)
in vec3 in_pos;
in vec2 in_uv;
in vec2 in_uvl;
in float in_kind;
out vec2 v_uv;
out vec2 v_uvl;
out vec3 v_world;
flat out float v_kind;
invariant gl_Position;
void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    gl_Position.z -= u_depth_bias * gl_Position.w;
    v_uv = in_uv;
    v_uvl = in_uvl;
    v_world = in_pos;
    v_kind = in_kind;
}
