#version 330 core
// Multiplies the terrain by the shadow (blend DST_COLOR, ZERO): 1 where the sun's view of the
// rider is empty, u_shade where it is covered; 1 (the frame buffer unchanged) outside the tile or
// in front of the caster (closer to the sun than the shadow frustum's near plane).  No discard:
// a shader that may discard loses llvmpipe's early depth test (and the clip distances of
// shadow_receiver.vert.glsl already cut the triangles to the frustum).
uniform sampler2D u_shadow;
uniform vec4 u_tile;    // x0, y0, width, height of this rider's tile in the shadow texture (0..1)
uniform vec3 u_shade;   // colour multiplier in full shadow
uniform sampler2D u_sunlit;  // 1 where the terrain sees the sun, 0 in its own shadow (no double darkening)
uniform vec4 u_sun_rect;     // x0, y0, width, height of u_sunlit over world xy
in vec3 v_light;
in vec3 v_world;
out vec4 f_color;
void main() {
    vec2 t = v_light.xy * 0.5 + 0.5;
    bool inside = all(greaterThanEqual(t, vec2(0.0))) && all(lessThanEqual(t, vec2(1.0))) && abs(v_light.z) <= 1.0;
    float s = texture(u_shadow, u_tile.xy + t * u_tile.zw).r
            * texture(u_sunlit, (v_world.xy - u_sun_rect.xy) / u_sun_rect.zw).r * (inside ? 1.0 : 0.0)
            * step(-3.0e38, v_world.z);  // exactly 1: see shadow_receiver_soft.frag.glsl
    f_color = vec4(mix(vec3(1.0), u_shade, s), 1.0);
}
