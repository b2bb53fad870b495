#version 330 core
// Projected shadows, step 2: the extra pass over the terrain patches a shadow frustum touches.
// Same position arithmetic as terrain.vert.glsl (invariant) so the pass lands on the terrain's
// depths; the shadow texture coordinates are the sun's orthographic projection of the vertex.
// The six clip distances are the shadow frustum's faces (|x|, |y|, |z| <= 1 in its clip space):
// with GL_CLIP_DISTANCE0..5 enabled (ShadowPass.draw_receivers) only the part of each terrain
// triangle inside the frustum is rasterized (the fragment shader leaves the rest unchanged
// anyway), where whole triangles reach far past a rider's shadow: on llvmpipe those pixels cost
// as much as the shadowed ones.
//
// Compiled with RECEIVER_RESIDENT 1 it reads the terrain's own resident vertex blocks (the buffer
// terrain.vert.glsl draws from: position, morph target, morph slot) and geomorphs as that shader
// does with this frame's factors (u_morph), so a frame sends only the shadowed triangles' indices.
uniform mat4 u_mvp;
uniform mat4 u_light_vp;
uniform float u_depth_bias;
in vec3 in_pos;
#if defined(RECEIVER_RESIDENT) && RECEIVER_RESIDENT == 1
uniform int u_morph_on;
uniform sampler2D u_morph;
in vec3 in_target;
in float in_morph;
#endif
out vec3 v_light;   // light clip coordinates (orthographic: w = 1)
out vec3 v_world;
out float gl_ClipDistance[6];
invariant gl_Position;
void main() {
    vec3 p = in_pos;
#if defined(RECEIVER_RESIDENT) && RECEIVER_RESIDENT == 1
    if (u_morph_on == 1) {
        int id = int(in_morph);
        float f = texelFetch(u_morph, ivec2(id & 1023, id >> 10), 0).r;
        p = in_target + f * (in_pos - in_target);
    }
#endif
    gl_Position = u_mvp * vec4(p, 1.0);
    gl_Position.z -= u_depth_bias * gl_Position.w;
    v_light = (u_light_vp * vec4(p, 1.0)).xyz;
    gl_ClipDistance[0] = 1.0 - v_light.x;
    gl_ClipDistance[1] = 1.0 + v_light.x;
    gl_ClipDistance[2] = 1.0 - v_light.y;
    gl_ClipDistance[3] = 1.0 + v_light.y;
    gl_ClipDistance[4] = 1.0 - v_light.z;
    gl_ClipDistance[5] = 1.0 + v_light.z;
    v_world = p;
}
