#version 330 core
// Projected shadows, step 1: a rider's low-LOD model seen from the sun (orthographic) into its
// tile of the shadow texture.
uniform mat4 u_light_vp;
in vec3 in_pos;
void main() {
    gl_Position = u_light_vp * vec4(in_pos, 1.0);
}
