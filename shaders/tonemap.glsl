// The one tone map, shared by the colour pass and the sky (included by programs.py; the
// Cycles twin applies the same formulas with numpy in glsynth/render/tonemap.py): linear
// radiance, already scaled by the exposure, to display sRGB.
// u_tone_map 0, "standard": clip to [0, 1], then the sRGB curve (Blender's Standard view
// transform). 1, "exponential": 1 - exp(-x) rolls highlights off, then gamma 2.2.
uniform int u_tone_map;

vec3 srgb_encode(vec3 c) {
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

vec3 tone_map(vec3 radiance) {
    if (u_tone_map == 1) return pow(vec3(1.0) - exp(-max(radiance, 0.0)), vec3(1.0 / 2.2));
    return srgb_encode(clamp(radiance, 0.0, 1.0));
}
