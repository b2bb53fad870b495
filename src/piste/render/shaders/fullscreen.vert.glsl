#version 330 core
// A full-screen triangle (no attributes): one fragment per pixel of the target (mip levels, resolve,
// FXAA, depth of field).
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2) * 2.0 - 1.0;
    gl_Position = vec4(p, 0.0, 1.0);
}
