#version 330 core
// Depth from the sun for the shadow map; the fragment stage only writes depth.
uniform mat4 u_light_mvp;  // light clip-from-mesh, composed in float64 on the CPU

in vec3 in_position;

void main() {
    gl_Position = u_light_mvp * vec4(in_position, 1.0);
}
