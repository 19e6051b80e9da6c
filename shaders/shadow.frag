#version 330 core
// Depth, and the part's own emitted radiance: the sky-visibility atlas keeps it as the light
// that comes from where a part hides the sky (the sun's shadow map has no colour to keep).
uniform vec3 u_radiance;
out vec4 f_radiance;

void main() {
    f_radiance = vec4(u_radiance, 1.0);
}
