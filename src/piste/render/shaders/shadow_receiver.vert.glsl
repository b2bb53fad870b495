#version 330 core
// Projected shadows, step 2: the extra pass over the terrain patches a shadow frustum touches.
// Same position arithmetic as terrain.vert.glsl (invariant) so the pass lands on the terrain's
// depths; the shadow texture coordinates are the sun's orthographic projection of the vertex.
uniform mat4 u_mvp;
uniform mat4 u_light_vp;
uniform float u_depth_bias;
in vec3 in_pos;
out vec3 v_light;   // light clip coordinates (orthographic: w = 1)
out vec3 v_world;
invariant gl_Position;
void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    gl_Position.z -= u_depth_bias * gl_Position.w;
    v_light = (u_light_vp * vec4(in_pos, 1.0)).xyz;
    v_world = in_pos;
}
