#version 330 core
// Riders (CPU-skinned with the blended-matrix palette, so positions and normals arrive in world
// space), lit per vertex as SSX does it: 1 ambient + 3 directional lights,
//     colour = ambient + C * max(D * n, 0)
// with D the light-direction matrix (rows: unit vectors towards the lights) and C the light-colour
// matrix (columns: the lights' colours), both chosen per rider (piste.lighting.vertex).
// Shared by the base pass and the specular pass (invariant: identical depths for GL_LEQUAL).
uniform mat4 u_mvp;
uniform mat3 u_light_dir;
uniform mat3 u_light_color;
uniform vec3 u_ambient;
in vec3 in_pos;
in vec3 in_nrm;
in vec2 in_uv;
out vec3 v_color;
out vec2 v_uv;
out vec3 v_world;
out vec3 v_normal;
invariant gl_Position;
void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    vec3 n = normalize(in_nrm);
    v_color = max(u_ambient + u_light_color * max(u_light_dir * n, vec3(0.0)), vec3(0.0));
    v_uv = in_uv;
    v_world = in_pos;
    v_normal = n;
}
