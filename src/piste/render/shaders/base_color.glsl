// The terrain's base colour Cd: the tiled snow texture, plus (when a track is given) a groomed
// piste: slightly cooler snow on the track and blue dye lines on its lips.  The track is a
// projected texture (the talk's third UV set): a signed distance across the track in metres,
// looked up by world x-y per vertex (``track_d``: terrain.vert.glsl's v_track_d, interpolated).
// Shared by the first pass and the PS2 light-map pass (which must see the same Cd).
uniform sampler2D u_base;
#ifdef TERRAIN_TRACK
const int u_track_on = TERRAIN_TRACK;  // compiled per track on / off (a run-time branch costs llvmpipe)
#else
uniform int u_track_on;
#endif
uniform float u_track_half;  // half width of the groomed track in metres

vec3 base_color(vec2 uv, float track_d) {
    vec3 c = texture(u_base, uv).rgb;
    if (u_track_on == 1) {
        float d = track_d;
        float ad = abs(d);
        // (one division a pixel: the screen width of a metre of d, inverted once; smoothstep over the
        // metre inside the lips written out, its span being 1; the tint as 1 - (0.05, 0.03, 0) g)
        float iw = 1.0 / max(fwidth(d), 1e-4);
        float t = clamp(ad - (u_track_half - 1.0), 0.0, 1.0);
        float groomed = 1.0 - t * t * (3.0 - 2.0 * t);
        c *= vec3(1.0) - vec3(0.05, 0.03, 0.0) * groomed;  // groomed snow: a little cooler (0.95, 0.97, 1)
        float hw = 0.3;  // the dye lines' half width, metres
        float line = clamp((hw - abs(ad - u_track_half)) * iw + 0.5, 0.0, 1.0) * min(1.0, 2.0 * hw * iw);
        c = mix(c, vec3(0.18, 0.32, 0.85), 0.85 * line);
    }
    return c;
}
