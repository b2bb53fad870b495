#version 330 core
// Projected shadows, step 1: a rider's low-LOD model seen from the sun (orthographic) into its
// tile of the shadow texture.
uniform mat4 u_light_vp;
in vec3 in_pos;
// (one interpolated vec3 the fragment shaders read without changing a value: the sky's set of
// interpolated inputs, so llvmpipe reuses the sky's triangle-setup function, which it compiles at a
// program's first draw without its shader cache: ~3.5 ms less in a fresh process's first frame)
out vec3 v_setup;
void main() {
    gl_Position = u_light_vp * vec4(in_pos, 1.0);
    v_setup = in_pos;
}
