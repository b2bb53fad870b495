#version 330 core
// Riders, first pass: texture x per-vertex light (u_mode 1: the vertex light alone, for tests),
// with the terrain's fog.
uniform sampler2D u_tex;
uniform vec3 u_eye;
uniform vec4 u_fog;   // rgb, density per metre (0: none)
uniform int u_mode;
in vec3 v_color;
in vec2 v_uv;
in vec3 v_world;
out vec4 f_color;
void main() {
    vec4 t = texture(u_tex, v_uv);
#ifdef CHARACTER_ALPHA_TEST
    // a glTF rider's alphaMode MASK (the cutoff baked into the texture's alpha: 0 or 255)
    if (u_mode != 1 && t.a < 0.5) discard;
#endif
    vec3 c = u_mode == 1 ? v_color : t.rgb * v_color;
    if (u_fog.a > 0.0) {
        c = mix(c, u_fog.rgb, 1.0 - exp(-u_fog.a * distance(v_world, u_eye)));
    }
    f_color = vec4(c, 1.0);
}
