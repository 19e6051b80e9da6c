// The one tone map, shared by the colour pass and the sky (included by programs.py): linear
// radiance, already scaled by the exposure, to display sRGB. 1 - exp(-x) rolls highlights off
// without hard clipping; gamma 2.2 approximates the sRGB transfer curve.
vec3 tone_map(vec3 radiance) {
    return pow(vec3(1.0) - exp(-radiance), vec3(1.0 / 2.2));
}
