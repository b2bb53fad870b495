#version 330 core
// Objects in their compressed vertex format, decoded here:
//   position  3 x uint16:  p = offset + extent * q / 65535   (per-mesh offset and extent)
//   uv        2 x uint16:  the same with the uv offset and extent
//   normal    2 x snorm8 or snorm16, octahedral:  o = max(c / cmax, -1); z = 1 - |x| - |y|; fold
// Per-instance data (one row of 16 RGBA32F texels per visible instance, row u_base_row +
// gl_InstanceID): object matrix (4 columns), normal matrix (3 columns, the inverse-transpose),
// light-direction matrix rows (3), light-colour matrix columns (3), ambient (+ the instance's row
// in the baked-colour texture in .w).
// u_mode: 0 dynamic (1 ambient + 3 directional, the talk's SSX scheme), 1 baked RGBs (half-bright
// RGB8, 128 = 1.0, per instance vertex), 2 dynamic point and spot lights (the full equation).
uniform mat4 u_vp;
uniform vec3 u_eye;
uniform vec4 u_fog;          // rgb, density per metre (0: none): the fog factor per vertex (v_fog)
uniform sampler2D u_inst;
uniform int u_base_row;
uniform vec3 u_pos_offset;
uniform vec3 u_pos_extent;
uniform vec2 u_uv_offset;
uniform vec2 u_uv_extent;
uniform float u_nmax;        // 127 or 32767
#ifndef OBJECT_MODE
uniform int u_mode;
#else
const int u_mode = OBJECT_MODE;  // compiled once per mode (a run-time if-chain costs llvmpipe's vertex work)
#endif
uniform sampler2D u_baked;   // (instances of this kind) x (vertices) RGBA8
// mode 2: every direct light of the world (up to 12)
uniform int u_n_lights;
uniform vec4 u_lpos[12];     // xyz position (or -direction for directional), w: 0 directional, 1 point, 2 spot
uniform vec4 u_ldir[12];     // xyz spot direction, w: range (0 = infinite)
uniform vec4 u_lcol[12];     // rgb intensity x colour, w: falloff
uniform vec4 u_lcone[12];    // cos(outer), cos(inner)
uniform vec3 u_world_ambient;
in uvec3 in_pos;
in uvec2 in_uv;
in ivec2 in_nrm;
out vec3 v_color;
out vec2 v_uv;
out vec3 v_world;
out float v_fog;

#ifdef OBJECT_INSTANCE_ATTRIBS
// the same 14 texels as per-instance vertex attributes (13 vec4: the normal-matrix and light-direction
// texels carry the ambient texel in their .w), fetched once per instance by the vertex stage instead of
// 14 texelFetch calls per vertex; inst() is inlined with constant columns and folds away
in vec4 in_i0, in_i1, in_i2, in_i3, in_i4, in_i5, in_i6, in_i7, in_i8, in_i9, in_i10, in_i11, in_i12;
vec4 inst(int col) {
    if (col == 0) return in_i0;
    if (col == 1) return in_i1;
    if (col == 2) return in_i2;
    if (col == 3) return in_i3;
    if (col == 4) return vec4(in_i4.xyz, 0.0);
    if (col == 5) return vec4(in_i5.xyz, 0.0);
    if (col == 6) return vec4(in_i6.xyz, 0.0);
    if (col == 7) return vec4(in_i7.xyz, 0.0);
    if (col == 8) return vec4(in_i8.xyz, 0.0);
    if (col == 9) return vec4(in_i9.xyz, 0.0);
    if (col == 10) return in_i10;
    if (col == 11) return in_i11;
    if (col == 12) return in_i12;
    return vec4(in_i4.w, in_i5.w, in_i6.w, in_i7.w);  // 13: ambient + the row in the baked colours
}
#else
vec4 inst(int col) { return texelFetch(u_inst, ivec2(col, u_base_row + gl_InstanceID), 0); }
#endif

vec3 oct_decode(ivec2 c) {
    vec2 o = max(vec2(c) / u_nmax, vec2(-1.0));
    float z = 1.0 - abs(o.x) - abs(o.y);
    float t = max(-z, 0.0);
    o.x += o.x >= 0.0 ? -t : t;
    o.y += o.y >= 0.0 ? -t : t;
    return normalize(vec3(o, z));
}

void main() {
    vec3 p = u_pos_offset + u_pos_extent * (vec3(in_pos) / 65535.0);
    vec3 n = oct_decode(in_nrm);
    mat4 model = mat4(inst(0), inst(1), inst(2), inst(3));
    mat3 nmat = mat3(inst(4).xyz, inst(5).xyz, inst(6).xyz);
    vec4 world = model * vec4(p, 1.0);
    vec3 wn = normalize(nmat * n);
    gl_Position = u_vp * world;
    v_world = world.xyz;
    v_fog = u_fog.a > 0.0 ? 1.0 - exp(-u_fog.a * distance(world.xyz, u_eye)) : 0.0;
    v_uv = u_uv_offset + u_uv_extent * (vec2(in_uv) / 65535.0);
    vec4 amb = inst(13);
    if (u_mode == 1) {
        v_color = texelFetch(u_baked, ivec2(gl_VertexID, int(amb.w + 0.5)), 0).rgb * (255.0 / 128.0);
    } else if (u_mode == 2) {
        vec3 c = u_world_ambient;
        for (int i = 0; i < u_n_lights; ++i) {
            vec3 L;
            float a = 1.0;
            if (u_lpos[i].w == 0.0) {
                L = u_lpos[i].xyz;
            } else {
                vec3 d = u_lpos[i].xyz - world.xyz;
                float dist = length(d);
                L = dist > 0.0 ? d / dist : vec3(0.0);
                if (u_ldir[i].w > 0.0) {
                    float x = 1.0 - min(dist / u_ldir[i].w, 1.0);
                    a = u_lcol[i].w == 0.0 ? step(1e-30, x) : pow(x, u_lcol[i].w);
                }
                if (u_lpos[i].w == 2.0) {
                    float ca = -dot(L, u_ldir[i].xyz);
                    a *= u_lcone[i].y > u_lcone[i].x ? smoothstep(u_lcone[i].x, u_lcone[i].y, ca) : step(u_lcone[i].y, ca);
                }
            }
            c += u_lcol[i].rgb * max(dot(wn, L), 0.0) * a;
        }
        v_color = max(c, vec3(0.0));
    } else {
        mat3 D = transpose(mat3(inst(7).xyz, inst(8).xyz, inst(9).xyz));  // rows: directions
        mat3 C = mat3(inst(10).xyz, inst(11).xyz, inst(12).xyz);           // columns: colours
        v_color = max(amb.xyz + C * max(D * wn, vec3(0.0)), vec3(0.0));
    }
}
