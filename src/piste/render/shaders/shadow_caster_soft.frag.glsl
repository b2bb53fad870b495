#version 330 core
// Soft shadows (PCSS), step 1: coverage in rgb (blend MAX) and the caster's nearest light depth in
// alpha (blend MIN), 0 at the shadow frustum's near plane (the front of the caster's bounding
// sphere) to 1 at its back (2 r further): 8 bits over a rider's ~2.5 m, ~1 cm a step.
uniform float u_depth_scale;  // (far - near) / (2 r): window depth -> 0..1 over the caster's sphere
in vec3 v_setup;
in vec3 v_setup2;  // (see shadow_caster.vert.glsl: the factor below is exactly 1)
out vec4 f_color;
void main() {
    f_color = vec4(1.0, 1.0, 1.0, clamp(gl_FragCoord.z * u_depth_scale, 0.0, 1.0))
            * step(-3.0e38, min(min(v_setup.x, min(v_setup.y, v_setup.z)), min(v_setup2.x, min(v_setup2.y, v_setup2.z))));
}
