#version 330 core
// Soft projected shadows: percentage-closer soft shadows (PCSS) from a sun of angular radius
// atan(u_tan).  1. blocker search: the caster texels inside the disc from which a caster at the
// shadow frustum's near plane could hide part of the sun give the mean blocker depth; 2. the
// penumbra's radius on this point, (receiver - blocker) * tan(sun radius); 3. PCF: the coverage
// averaged over that disc (bilinear, mip-filtered samples), which is the shadowed fraction of the
// sun's disc for a caster lying at the blocker depth.  No blocker found, or a penumbra within
// the bilinear sample's own blur: the hard shadow's one sample.  Same outputs as shadow_receiver.frag.glsl.
uniform sampler2D u_shadow;
uniform vec4 u_tile;    // x0, y0, width, height of this rider's tile in the shadow texture (0..1)
uniform vec3 u_shade;   // colour multiplier in full shadow
uniform sampler2D u_sunlit;
uniform vec4 u_sun_rect;
uniform float u_tan;    // tan(the sun's angular radius)
uniform vec2 u_span;    // metres: the tile's width (2 r) and the light frustum's depth (far - near)
uniform float u_texel;  // one texel in tile coordinates (1 / tile)
in vec3 v_light;
in vec3 v_world;
out vec4 f_color;

const int N_SEARCH = 16;
const int N_PCF = 32;

vec2 disc(int i, int n) {  // Vogel's spiral: n points spread evenly over the unit disc
    float r = sqrt((float(i) + 0.5) / float(n));
    float a = float(i) * 2.39996323;
    return r * vec2(cos(a), sin(a));
}

vec2 in_tile(vec2 t) {  // tile coordinates -> texture coordinates, kept off the neighbours' texels
    return u_tile.xy + clamp(t, vec2(0.5 * u_texel), vec2(1.0 - 0.5 * u_texel)) * u_tile.zw;
}

void main() {
    vec2 t = v_light.xy * 0.5 + 0.5;
    float foot = max(length(dFdx(t)), length(dFdy(t))) / u_texel;  // the pixel's footprint, texels
    if (any(lessThan(t, vec2(0.0))) || any(greaterThan(t, vec2(1.0))) || v_light.z < -1.0 || v_light.z > 1.0) {
        discard;
    }
    float zr = (v_light.z * 0.5 + 0.5) * u_span.y;   // metres behind the near plane
    float search = zr * u_tan / u_span.x + u_texel;  // tile units
    ivec2 size = textureSize(u_shadow, 0);
    float sum = 0.0;
    float count = 0.0;
    for (int i = 0; i < N_SEARCH; ++i) {
        vec4 b = texelFetch(u_shadow, ivec2(in_tile(t + search * disc(i, N_SEARCH)) * vec2(size)), 0);
        if (b.r > 0.5) {
            sum += b.a;
            count += 1.0;
        }
    }
    // no blocker among the search's texels: the hard shadow's mip-filtered sample (a distant rider's
    // thin limbs fall between point samples; lit points read 0 here anyway)
    float s = texture(u_shadow, in_tile(t)).r;
    if (count > 0.0) {
        float zb = sum / count * u_span.x;                        // the blockers' mean depth, metres
        float pen = max(zr - zb, 0.0) * u_tan / u_span.x;        // penumbra radius, tile units
        // less the bilinear samples' own blur (a tent of one texel: the spread of a disc of radius
        // 0.82 texel), so that the two together spread as the penumbra's disc does
        float pen2 = pen * pen - 0.667 * u_texel * u_texel;
        if (pen2 <= 0.0) {
            s = texture(u_shadow, in_tile(t)).r;
        } else {
            // the disc filters what is under it: mip levels only for a pixel wider than the disc
            float lod = max(0.0, log2(max(foot, 1.0) / max(2.0 * sqrt(pen2) / u_texel, 1.0)));
            for (int i = 0; i < N_PCF; ++i) {
                s += textureLod(u_shadow, in_tile(t + sqrt(pen2) * disc(i, N_PCF)), lod).r;
            }
            s /= float(N_PCF);
        }
    }
    // (x step(-3e38, v_world.z): exactly 1 for any height, so the value is unchanged; reading z keeps
    // v_world whole, which gives this program the terrain's and objects' set of interpolated inputs
    // (2 vec4 slots, all read): llvmpipe then reuses their triangle-setup function, which it compiles
    // at a program's first draw without its shader cache, ~3.5 ms of a fresh process's first frame)
    s *= texture(u_sunlit, (v_world.xy - u_sun_rect.xy) / u_sun_rect.zw).r * step(-3.0e38, v_world.z);
    f_color = vec4(mix(vec3(1.0), u_shade, s), 1.0);
}
