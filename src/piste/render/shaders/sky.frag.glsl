#version 330 core
// Gradient sky: horizon haze to zenith blue by the view ray's elevation, plus a soft sun glow.
uniform mat4 u_inv_vp;
uniform vec3 u_horizon;
uniform vec3 u_zenith;
uniform vec3 u_sun;
in vec2 v_ndc;
out vec4 f_color;
void main() {
    vec4 a = u_inv_vp * vec4(v_ndc, -1.0, 1.0);
    vec4 b = u_inv_vp * vec4(v_ndc, 1.0, 1.0);
    vec3 d = normalize(b.xyz / b.w - a.xyz / a.w);
    float h = clamp(d.z, 0.0, 1.0);
    vec3 c = mix(u_horizon, u_zenith, 1.0 - exp(-2.2 * h));
    c = mix(c, u_horizon * 0.9, 1.0 - exp(min(d.z, 0.0) * 3.0));  // a little darker below the horizon
    float s = max(dot(d, u_sun), 0.0);
    c += vec3(1.0, 0.95, 0.85) * (0.25 * pow(s, 24.0) + 0.6 * pow(s, 900.0));
    f_color = vec4(min(c, vec3(1.0)), 1.0);
}
