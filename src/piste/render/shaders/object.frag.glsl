#version 330 core
// Objects: texture x per-vertex light (u_mode_frag 1: the light alone, for tests), fog.
uniform sampler2D u_tex;
uniform vec4 u_fog;
#ifndef OBJECT_MODE_FRAG
uniform int u_mode_frag;
#else
const int u_mode_frag = OBJECT_MODE_FRAG;
#endif
#ifndef OBJECT_ALPHA_TEST
#define OBJECT_ALPHA_TEST 1
#endif
#ifndef OBJECT_BLEND
#define OBJECT_BLEND 0
#endif
in vec3 v_color;
in vec2 v_uv;
in float v_fog;   // 1 - exp(-density x distance), per vertex
out vec4 f_color;
void main() {
    vec4 t = texture(u_tex, v_uv);
#if OBJECT_ALPHA_TEST
    // glTF alphaMode MASK / BLEND (pipeline.object_atlas bakes the cutoff); compiled out when no texel
    // of the atlas is below the cutoff (a shader that may discard loses llvmpipe's early depth test)
    if (u_mode_frag != 1 && t.a < 0.5) discard;
#endif
    vec3 c = u_mode_frag == 1 ? v_color : t.rgb * v_color;
    if (u_fog.a > 0.0) {
        c = mix(c, u_fog.rgb, v_fog);
    }
#if OBJECT_BLEND
    // glTF alphaMode BLEND: the texel's alpha (the blend pass: SRC_ALPHA, ONE_MINUS_SRC_ALPHA)
    f_color = vec4(c, u_mode_frag == 1 ? 1.0 : t.a);
#else
    f_color = vec4(c, 1.0);
#endif
}
