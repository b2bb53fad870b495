#version 330 core
out vec4 f_color;
void main() {
    f_color = vec4(1.0);
}
