#version 430
// Two mip levels of an RGBA8 texture in one dispatch (the shadow texture's levels without a
// framebuffer per level: on llvmpipe each framebuffer change waits for the rasterizer).  One
// invocation per texel of level l + 2: it reads the 4 x 4 texels of level l (u_src: level l bound
// as an image; imageLoad, where texelFetch through a sampler with a per-lane level cost llvmpipe
// ~3x as much: the shadow texture's 4 levels 0.20 ms instead of 0.57) under it and writes the 2 x 2 texels of level l + 1 and the texel of level l + 2 with the same
// arithmetic as mip_level.frag.glsl and Mesa's glGenerateMipmap on llvmpipe: horizontal pairs
// averaged and rounded half up to 8 bits, then those vertically.  Every side of level l must be a
// multiple of 4 (the levels halve exactly).
layout(local_size_x = 8, local_size_y = 8) in;
layout(rgba8, binding = 2) readonly uniform image2D u_src;  // level l
uniform ivec2 u_size;  // level l + 2's size
layout(rgba8, binding = 0) writeonly uniform image2D u_next;   // level l + 1
layout(rgba8, binding = 1) writeonly uniform image2D u_next2;  // level l + 2

vec4 texel(ivec2 p) {
    return floor(imageLoad(u_src, p) * 255.0 + 0.5);
}

vec4 down(vec4 a, vec4 b, vec4 c, vec4 d) {  // a b on the lower row, c d above, 0..255
    return floor((floor((a + b + 1.0) * 0.5) + floor((c + d + 1.0) * 0.5) + 1.0) * 0.5);
}

vec4 next(ivec2 q) {  // the texel q of level l + 1, written and returned
    ivec2 p = 2 * q;
    vec4 v = down(texel(p), texel(p + ivec2(1, 0)), texel(p + ivec2(0, 1)), texel(p + ivec2(1, 1)));
    imageStore(u_next, q, v / 255.0);
    return v;
}

void main() {
    ivec2 r = ivec2(gl_GlobalInvocationID.xy);
    if (r.x >= u_size.x || r.y >= u_size.y) {
        return;
    }
    ivec2 q = 2 * r;
    vec4 v = down(next(q), next(q + ivec2(1, 0)), next(q + ivec2(0, 1)), next(q + ivec2(1, 1)));
    imageStore(u_next2, r, v / 255.0);
}
