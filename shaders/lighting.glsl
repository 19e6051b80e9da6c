// The colour pass's lighting (color.frag), in its own file so that the shader harness tests
// the very functions the colour pass runs (tests/test_lighting_shader.py): the sRGB curve,
// spherical-harmonic irradiance, the BRDF (GGX specular, Burley diffuse) under the sun, and
// the ambient light of sky and ground.
uniform vec3 u_sun_dir;       // camera space, towards the sun
uniform vec3 u_sun_color;
uniform mat3 u_world_from_view;
uniform vec3 u_sh_sky[9];     // irradiance = sum u_sh[i] Y_i(world normal) (glsynth.world.lighting)
uniform vec3 u_sh_ground[9];

uniform bool u_has_ao;
uniform sampler2D u_ao;       // per pixel, from the ssao programs; 1: unoccluded

const float PI = 3.14159265358979;

// The exact sRGB curve, as Blender decodes colour textures.
vec3 srgb_to_linear(vec3 c) {
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(0.04045, c));
}

float[9] sh_basis(vec3 n) {  // real SH basis, in the order of glsynth.world.lighting.sh_basis
    return float[9](0.282095, 0.488603 * n.y, 0.488603 * n.z, 0.488603 * n.x,
                    1.092548 * n.x * n.y, 1.092548 * n.y * n.z,
                    0.315392 * (3.0 * n.z * n.z - 1.0), 1.092548 * n.x * n.z,
                    0.546274 * (n.x * n.x - n.y * n.y));
}

vec3 sh_irradiance(vec3 c[9], vec3 n) {
    float y[9] = sh_basis(n);
    vec3 e = vec3(0.0);
    for (int i = 0; i < 9; ++i) e += c[i] * y[i];
    return max(e, 0.0);
}

// The surface's material at this fragment: base colour (linear), metallic, roughness, and
// the reflectance at normal incidence.
struct Surface {
    vec3 base;
    float metallic;
    float roughness;
    vec3 f0;
};

// GGX specular: Trowbridge-Reitz distribution, Smith-Schlick shadowing, Schlick Fresnel.
vec3 ggx_specular(float nl, float nv, float nh, float vh, float roughness, vec3 f0) {
    float alpha = roughness * roughness;
    float a2 = alpha * alpha;
    float denom = nh * nh * (a2 - 1.0) + 1.0;
    float D = a2 / (PI * denom * denom);
    float k = (roughness + 1.0) * (roughness + 1.0) / 8.0;
    float G = (nl / (nl * (1.0 - k) + k)) * (nv / (nv * (1.0 - k) + k));
    vec3 F = f0 + (1.0 - f0) * pow(1.0 - vh, 5.0);
    return D * G * F / max(4.0 * nl * nv, 1e-4);
}

// Burley's diffuse with retro-reflection, as Cycles' Principled BSDF evaluates it (the glTF
// importer's material): not reduced by the specular layer's Fresnel. lv: dot(l, v).
float burley_diffuse(float nl, float nv, float lv, float roughness) {
    float fl = pow(1.0 - nl, 5.0), fv = pow(1.0 - nv, 5.0);
    float rr = roughness * (1.0 + lv);
    return (1.0 - 0.5 * fl) * (1.0 - 0.5 * fv) + rr * (fl + fv + fl * fv * (rr - 1.0));
}

// The sun's light that normal n reflects towards v, before its shadow.
vec3 sun_light(Surface s, vec3 n, vec3 v) {
    vec3 l = normalize(u_sun_dir);
    vec3 h = normalize(l + v);
    float nl = max(dot(n, l), 0.0), nv = max(dot(n, v), 1e-4);
    float nh = max(dot(n, h), 0.0), vh = max(dot(v, h), 0.0);
    vec3 specular = ggx_specular(nl, nv, nh, vh, s.roughness, s.f0);
    vec3 diffuse = burley_diffuse(nl, nv, dot(l, v), s.roughness) * (1.0 - s.metallic) * s.base
                   / PI;
    return (diffuse + specular) * u_sun_color * nl;
}

// Ambient: diffuse by the normal; specular by the reflected direction, where the
// cosine-filtered radiance (irradiance / pi) stands in for the prefiltered radiance: exact
// for the widest lobe and close for the rough concrete that fills these scenes. vis and
// hidden: from sky_visibility.
vec3 ambient_light(Surface s, vec3 n, vec3 v, vec2 vis, vec3 hidden) {
    vec3 r = reflect(-v, n);
    // The sky through its visibility, plus the light of the emitting parts that hide it. The
    // ground's light through the point's mean openness, but at least a quarter of it: a point
    // under the deck sees the ground the deck shades, and beyond it (for a deck as wide as it
    // is high, about a quarter of the cosine-weighted view down) ground in full light.
    // (Finding the shaded ground through the sun's map measured no better.)
    vec3 nw = u_world_from_view * n, rw = u_world_from_view * r;
    float ground = mix(0.25, 1.0, vis.y);
    vec3 env_diffuse = (sh_irradiance(u_sh_sky, nw) * vis.x
                        + sh_irradiance(u_sh_ground, nw) * ground + hidden) / PI;
    vec3 env_specular = (sh_irradiance(u_sh_sky, rw) * vis.x
                         + sh_irradiance(u_sh_ground, rw) * ground) / PI;
    float nv = max(dot(n, v), 1e-4);
    vec3 f_env = s.f0 + (max(vec3(1.0 - s.roughness), s.f0) - s.f0) * pow(1.0 - nv, 5.0);
    vec3 ambient = (1.0 - s.metallic) * s.base * env_diffuse
                 + f_env * env_specular * (1.0 - 0.7 * s.roughness);
    if (u_has_ao) ambient *= texelFetch(u_ao, ivec2(gl_FragCoord.xy), 0).r;
    return ambient;
}
