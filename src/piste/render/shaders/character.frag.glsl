#version 330 core
// Riders, first pass: texture x per-vertex light (u_mode 1: the vertex light alone, for tests),
// with the terrain's fog.  Compiled with CHARACTER_SPECULAR (CharacterPass.fold_specular): the
// specular-map highlights of character_specular.frag.glsl added here, in the same pass (the talk's
// second pass adds them with ONE, ONE blending over the same depths: the same sum, rounded once).
uniform sampler2D u_tex;
uniform vec3 u_eye;
uniform vec4 u_fog;   // rgb, density per metre (0: none)
uniform int u_mode;
#ifdef CHARACTER_SPECULAR
uniform sampler2D u_spec;   // r: specular strength, g: shininess scale
uniform vec3 u_sun_dir;     // unit vector towards the sun
uniform vec3 u_sun_color;   // intensity x colour
uniform float u_shininess;
in vec3 v_normal;
#endif
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
    float f = u_fog.a > 0.0 ? exp(-u_fog.a * distance(v_world, u_eye)) : 1.0;
    if (u_fog.a > 0.0) {
        c = mix(c, u_fog.rgb, 1.0 - f);
    }
#ifdef CHARACTER_SPECULAR
    // (the base colour is clamped to 0..1 before the highlight is added, as the 8-bit frame buffer
    // clamps the first pass before the second pass's blend)
    vec4 s = texture(u_spec, v_uv);
    vec3 n = normalize(v_normal);
    vec3 v = normalize(u_eye - v_world);
    vec3 h = normalize(u_sun_dir + v);
    float lit = step(0.0, dot(n, u_sun_dir));
    float spec = lit * s.r * pow(max(dot(n, h), 0.0), u_shininess * (0.25 + s.g));
    c = clamp(c, 0.0, 1.0) + spec * u_sun_color * f;
#endif
    f_color = vec4(c, 1.0);
}
