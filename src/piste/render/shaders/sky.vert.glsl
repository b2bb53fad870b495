#version 330 core
// A full-screen triangle on the far plane (depth 1.0): drawn after the terrain with depth test
// LEQUAL it only shades the pixels the terrain left empty.  Each corner carries its view ray (far
// point minus near point, both unprojected): for a perspective or orthographic camera the
// unprojected points' w is the same all over the screen, so the ray is linear in the screen and
// interpolating it is exact (the fragment shader only normalises it).
uniform mat4 u_inv_vp;
out vec3 v_ray;
out vec3 v_setup;  // (read by sky.frag.glsl without changing a value: see there)
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2) * 2.0 - 1.0;
    vec4 a = u_inv_vp * vec4(p, -1.0, 1.0);
    vec4 b = u_inv_vp * vec4(p, 1.0, 1.0);
    v_ray = b.xyz / b.w - a.xyz / a.w;
    v_setup = a.xyz;
    gl_Position = vec4(p, 1.0, 1.0);
}
