#version 330 core
in vec3 v_setup;
in vec3 v_setup2;  // (see shadow_caster.vert.glsl: the factor below is exactly 1)
out vec4 f_color;
void main() {
    f_color = vec4(step(-3.0e38, min(min(v_setup.x, min(v_setup.y, v_setup.z)), min(v_setup2.x, min(v_setup2.y, v_setup2.z)))));
}
