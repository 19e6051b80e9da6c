// The one tone map, shared by the colour pass and the sky (included by programs.py; the
// Cycles twin applies the same formulas with numpy in glsynth/render/tonemap.py): linear
// radiance, already scaled by the exposure, to display sRGB: clip to [0, 1], then the sRGB
// curve (Blender's Standard view transform).

vec3 srgb_encode(vec3 c) {
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

vec3 tone_map(vec3 radiance) {
    return srgb_encode(clamp(radiance, 0.0, 1.0));
}
