#version 330 core
// Gradient sky: horizon haze to zenith blue by the view ray's elevation, plus a soft sun glow.
// Above the horizon the colour goes from u_horizon towards u_zenith by 1 - exp(-2.2 z), below it
// towards 0.9 u_horizon by 1 - exp(3 z) (a little darker): one exp a pixel (one of the two terms is
// always 0).  The glow 0.25 s^24 + 0.6 s^900 (s: cosine of the angle to the sun) by squaring, no
// pow (log2 + exp2 a pixel cost llvmpipe more), and only where s > 0.75: below that the glow is
// under 0.25 0.75^24 < 2e-4 (far below half a step of 8 bits) and the ray's colour is the gradient's.
uniform vec3 u_horizon;
uniform vec3 u_zenith;
uniform vec3 u_sun;
in vec3 v_ray;
in vec3 v_setup;  // the near point (any finite vec3): x a factor exactly 1, so that the sky's interpolated
                  // inputs are the terrain's and llvmpipe reuses its triangle-setup function (see
                  // shadow_caster.vert.glsl)
out vec4 f_color;
void main() {
    vec3 d = normalize(v_ray);
    bool up = d.z > 0.0;
    float e = exp(up ? -2.2 * min(d.z, 1.0) : 3.0 * d.z);
    vec3 c = mix(u_horizon, up ? u_zenith : u_horizon * 0.9, 1.0 - e);
    float s = dot(d, u_sun);
    if (s > 0.75) {
        float s2 = s * s;
        float s4 = s2 * s2;
        float s8 = s4 * s4;
        float s16 = s8 * s8;
        float s24 = s16 * s8;
        float s128 = s16 * s16;
        s128 *= s128;
        s128 *= s128;
        float s256 = s128 * s128;
        float s512 = s256 * s256;
        c += vec3(1.0, 0.95, 0.85) * (0.25 * s24 + 0.6 * (s512 * s256 * s128 * s4));
    }
    f_color = vec4(min(c, vec3(1.0)), 1.0) * step(-3.0e38, min(v_setup.x, min(v_setup.y, v_setup.z)));
}
