#version 330 core
// SSX light-map source pass (piste.render.ssx_pass): the terrain's positions and light-map UVs.
// Same clip-space arithmetic as the terrain's first pass, so the depths match.
uniform mat4 u_mvp;
uniform float u_depth_bias;
in vec3 in_pos;
in vec2 in_uvl;
out vec2 v_uvl;
invariant gl_Position;
void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    gl_Position.z -= u_depth_bias * gl_Position.w;
    v_uvl = in_uvl;
}
