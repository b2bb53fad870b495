#version 330 core
// An SSX Tricky level's stored light-map texels: RGB = Cs, A = As (128 = 1.0, up to 255).  The
// GS blends (Cd - Cs) x As >> 7 over the base texture already in the frame buffer.  GL blend
// factors stop at 1.0, so the renderer splits As in two stages:
//   u_stage 0: output (Cs, min(As, 1)) blended FUNC_REVERSE_SUBTRACT (SRC_ALPHA, SRC_ALPHA):
//              dst = (Cd - Cs) x min(As, 1)
//   u_stage 1: output max(As - 1, 0) blended FUNC_ADD (DST_COLOR, ONE): dst += dst x (As - 1),
//              only drawn when some As > 1 (over-bright)
//   u_stage 2: the raw texel (Cs, As / 2) without blending (tests read it back)
uniform sampler2D u_source;
uniform int u_stage;
in vec2 v_uvl;
out vec4 f_color;
void main() {
    vec4 t = texture(u_source, v_uvl);
    float as_ = t.a * (255.0 / 128.0);
    if (u_stage == 0) {
        f_color = vec4(t.rgb, min(as_, 1.0));
    } else if (u_stage == 1) {
        f_color = vec4(vec3(max(as_ - 1.0, 0.0)), 1.0);
    } else {
        f_color = vec4(t.rgb, t.a);
    }
}
