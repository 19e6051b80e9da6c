// Sky radiance in a world direction (z up), shared by the background and nothing else: the
// ambient light comes from the same model through spherical harmonics computed on the CPU
// (glsynth/world/lighting.py holds the same model in numpy, and the documentation).
uniform int u_sky_model;       // 0 Preetham, 1 uniform
uniform vec3 u_sky_uniform;    // uniform sky radiance (strength included)
uniform vec3 u_sky_zenith;     // Preetham zenith (Y x 0.06, x, y)
uniform float u_sky_perez[15]; // Perez A-E for Y, then x, then y
uniform vec3 u_sky_sun;        // towards the sun, at or above the horizon
uniform float u_sky_strength;

float perez(int k, float cos_theta, float gamma) {
    int o = 5 * k;
    float cg = cos(gamma);
    return (1.0 + u_sky_perez[o] * exp(u_sky_perez[o + 1] / cos_theta)) *
           (1.0 + u_sky_perez[o + 2] * exp(u_sky_perez[o + 3] * gamma) +
            u_sky_perez[o + 4] * cg * cg);
}

vec3 sky_radiance(vec3 d) {
    if (u_sky_model == 1) return u_sky_uniform;
    float gamma = acos(clamp(dot(d, u_sky_sun), -1.0, 1.0));
    float cos_theta = cos(min(acos(clamp(d.z, -1.0, 1.0)), 1.5697963));  // pi/2 - 0.001
    float lum = u_sky_zenith.x * perez(0, cos_theta, gamma);
    float x = u_sky_zenith.y * perez(1, cos_theta, gamma);
    float y = u_sky_zenith.z * perez(2, cos_theta, gamma);
    vec3 xyz = y != 0.0 ? vec3(x / y * lum, lum, (1.0 - x - y) / y * lum) : vec3(0.0);
    mat3 to_rgb = mat3(3.2404542, -0.9692660, 0.0556434,    // columns: XYZ to linear Rec.709
                       -1.5371385, 1.8760108, -0.2040259,
                       -0.4985314, 0.0415560, 1.0572252);
    return u_sky_strength * (to_rgb * xyz);
}
