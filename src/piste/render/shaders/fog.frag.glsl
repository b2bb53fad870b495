#version 330 core
// Fog as a blended pass (for the PS2 light-map mode, whose colour is finished by the blend):
// outputs the fog colour with alpha = fog factor; blended SRC_ALPHA, ONE_MINUS_SRC_ALPHA.
uniform vec3 u_eye;
uniform vec4 u_fog;
in vec3 v_world;
out vec4 f_color;
void main() {
    f_color = vec4(u_fog.rgb, 1.0 - exp(-u_fog.a * distance(v_world, u_eye)));
}
