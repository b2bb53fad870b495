#version 330 core
// Projected shadows, step 1: a rider's low-LOD model seen from the sun (orthographic) into its
// tile of the shadow texture.
uniform mat4 u_light_vp;
in vec3 in_pos;
// (two interpolated vec3s the fragment shaders read without changing a value: the terrain's set of
// interpolated inputs (two vec4 slots, all read; the sky's, the receivers' and the objects' too), so
// llvmpipe reuses one triangle-setup function for them all: it compiles one at the first draw of
// each new set, without its shader cache, ~3.5 ms of a fresh process's first frame)
out vec3 v_setup;
out vec3 v_setup2;
void main() {
    gl_Position = u_light_vp * vec4(in_pos, 1.0);
    v_setup = in_pos;
    v_setup2 = gl_Position.xyz;
}
