#version 330 core
// One texel of mip level l from its 2 x 2 parents in level l - 1 (the texture's base and max level
// while this draws, so lod 0 here is level l - 1): the horizontal pairs averaged and rounded half
// up to 8 bits, then those vertically, as Mesa's glGenerateMipmap on llvmpipe and
// piste.render.textures.mip_chain compute it.  An axis of one texel uses its texel twice.
uniform sampler2D u_src;
out vec4 f_color;
void main() {
    ivec2 size = textureSize(u_src, 0);
    ivec2 p = 2 * ivec2(gl_FragCoord.xy);
    ivec2 q = min(p + 1, size - 1);
    vec4 a = floor(texelFetch(u_src, p, 0) * 255.0 + 0.5);
    vec4 b = floor(texelFetch(u_src, ivec2(q.x, p.y), 0) * 255.0 + 0.5);
    vec4 c = floor(texelFetch(u_src, ivec2(p.x, q.y), 0) * 255.0 + 0.5);
    vec4 d = floor(texelFetch(u_src, q, 0) * 255.0 + 0.5);
    vec4 top = floor((a + b + 1.0) * 0.5);
    vec4 bottom = floor((c + d + 1.0) * 0.5);
    f_color = floor((top + bottom + 1.0) * 0.5) / 255.0;
}
