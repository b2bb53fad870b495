#version 330 core
// Riders, second pass (the talk's "specular map (second pass)"): Blinn-Phong highlights of the
// sun, scaled by a specular map (goggles, board, jacket), added on top with additive blending
// (ONE, ONE) over the same depths (GL_LEQUAL).  Faded by the fog like the first pass.
uniform sampler2D u_spec;
uniform vec3 u_eye;
uniform vec4 u_fog;
uniform vec3 u_sun_dir;     // unit vector towards the sun
uniform vec3 u_sun_color;   // intensity x colour
uniform float u_shininess;
in vec3 v_color;
in vec2 v_uv;
in vec3 v_world;
in vec3 v_normal;
out vec4 f_color;
void main() {
    vec4 s = texture(u_spec, v_uv);       // r: specular strength, g: shininess scale
    vec3 n = normalize(v_normal);
    vec3 v = normalize(u_eye - v_world);
    vec3 h = normalize(u_sun_dir + v);
    float lit = step(0.0, dot(n, u_sun_dir));
    float spec = lit * s.r * pow(max(dot(n, h), 0.0), u_shininess * (0.25 + s.g));
    float f = u_fog.a > 0.0 ? exp(-u_fog.a * distance(v_world, u_eye)) : 1.0;
    f_color = vec4(spec * u_sun_color * f, 0.0);
}
