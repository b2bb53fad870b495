#version 330 core
// The PS2 light-map pass (GDC 2002, "Visual Engineering of SSX"): the GS cannot multiply the
// frame buffer by a texture, but it can blend (Cd - Cs) x As.  With
//     As = max(CL.r, CL.g, CL.b)      Cs = Cd - Cd x CL / As
// the blend gives (Cd - Cs) x As = Cd x CL.  Cd is the base texture already in the frame buffer;
// this pass samples the same base texture to derive Cs per texel and outputs (Cs, As).  The
// blend is set up by the renderer: FUNC_REVERSE_SUBTRACT with SRC_ALPHA, SRC_ALPHA for colour
// (dst x As - src x As) and ZERO, ONE for alpha (destination alpha kept).
#include "base_color.glsl"
uniform sampler2D u_light;
in vec2 v_uv;
in vec2 v_uvl;
in float v_track_d;
out vec4 f_color;
void main() {
    vec3 cd = base_color(v_uv, v_track_d);
    vec3 cl = texture(u_light, v_uvl).rgb;
    float as_ = max(cl.r, max(cl.g, cl.b));
    vec3 cs = as_ > 0.0 ? cd - cd * cl / as_ : vec3(0.0);
    f_color = vec4(cs, as_);
}
