#version 330 core
// The background where no geometry is drawn: the sky colour through the shared tone map. The
// renderer draws it once into one pixel and clears each colour target to that value.
#include "tonemap.glsl"

uniform vec3 u_sky_color;  // linear RGB
uniform float u_exposure;

out vec4 f_color;

void main() {
    f_color = vec4(tone_map(u_sky_color * u_exposure), 1.0);
}
