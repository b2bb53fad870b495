#version 330 core
// Fog as a blended pass (for the PS2 light-map mode, whose colour is finished by the blend):
// outputs the fog colour with alpha = fog factor; blended SRC_ALPHA, ONE_MINUS_SRC_ALPHA.
uniform vec4 u_fog;
in float v_fog;     // 1 - exp(-density x distance), per vertex (terrain.vert.glsl)
out vec4 f_color;
void main() {
    f_color = vec4(u_fog.rgb, v_fog);
}
