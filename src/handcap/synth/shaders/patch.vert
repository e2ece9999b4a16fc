// Vertex shader of handcap.synth.images: world positions through the camera's projection.
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
out vec3 v_pos;
out vec3 v_normal;
out vec2 v_uv;
void main() {
    v_pos = in_pos;
    v_normal = in_normal;
    v_uv = in_uv;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
