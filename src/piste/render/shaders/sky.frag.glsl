#version 330 core
// Gradient sky: horizon haze to zenith blue by the view ray's elevation, plus a soft sun glow.
uniform vec3 u_horizon;
uniform vec3 u_zenith;
uniform vec3 u_sun;
in vec3 v_ray;
out vec4 f_color;
void main() {
    vec3 d = normalize(v_ray);
    float h = clamp(d.z, 0.0, 1.0);
    vec3 c = mix(u_horizon, u_zenith, 1.0 - exp(-2.2 * h));
    c = mix(c, u_horizon * 0.9, 1.0 - exp(min(d.z, 0.0) * 3.0));  // a little darker below the horizon
    float s = max(dot(d, u_sun), 0.0);
    float s3 = s * s * s;
    float s24 = s3 * s3;
    s24 *= s24;
    s24 *= s24;  // s^24 by squaring (a pow per pixel costs llvmpipe more)
    c += vec3(1.0, 0.95, 0.85) * (0.25 * s24 + 0.6 * pow(s, 900.0));
    f_color = vec4(min(c, vec3(1.0)), 1.0);
}
