#version 330 core
// A full-screen triangle on the far plane (depth 1.0): drawn after the terrain with depth test
// LEQUAL it only shades the pixels the terrain left empty.  The fragment shader turns each pixel
// into a view ray.
out vec2 v_ndc;
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2) * 2.0 - 1.0;
    v_ndc = p;
    gl_Position = vec4(p, 1.0, 1.0);
}
