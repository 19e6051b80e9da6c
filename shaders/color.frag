#version 330 core
// Metallic-roughness PBR: GGX specular + Lambert diffuse under one sun and a sky/ground
// hemisphere, plus emission (scene panels are emission-only). The normal map (the damage
// normal map on damaged columns) perturbs the normal in a tangent frame built from screen-space
// derivatives of position and UV, so meshes need no tangent attribute. The sun is shadowed by
// a shadow map (3x3 percentage-closer filtering) where u_has_shadows is set.
in vec3 v_view_pos;
in vec3 v_normal;
in vec2 v_uv;

uniform vec4 u_base_color;
uniform float u_metallic;
uniform float u_roughness;
uniform vec3 u_emissive;
uniform sampler2D u_base_color_map;          // sRGB; 1x1 white when the material has none
uniform sampler2D u_metallic_roughness_map;  // glTF: G roughness, B metallic; 1x1 white if none
uniform sampler2D u_emissive_map;            // sRGB; 1x1 white if none
uniform sampler2D u_normal_map;              // tangent space, 1x1 (0.5, 0.5, 1) if none
uniform bool u_has_normal_map;

uniform vec3 u_sun_dir;       // camera space, towards the sun
uniform vec3 u_sun_color;
uniform vec3 u_up;            // camera space world up
uniform vec3 u_sky_color;
uniform vec3 u_ground_color;
uniform float u_exposure;

uniform bool u_has_shadows;
uniform sampler2DShadow u_shadow_map;
uniform mat4 u_shadow_from_view;   // shadow-map texture coordinates and depth, all in [0, 1]
uniform float u_shadow_texel;      // 1 / map size
uniform float u_shadow_offset_m;   // lookups move this far along the normal (against acne)

out vec4 f_color;

#include "tonemap.glsl"

const float PI = 3.14159265358979;

vec3 srgb_to_linear(vec3 c) { return pow(c, vec3(2.2)); }

vec3 perturbed_normal(vec3 n, vec3 view_dir) {
    vec3 dp1 = dFdx(v_view_pos), dp2 = dFdy(v_view_pos);
    vec2 duv1 = dFdx(v_uv), duv2 = dFdy(v_uv);
    vec3 dp2perp = cross(dp2, n), dp1perp = cross(n, dp1);
    vec3 t = dp2perp * duv1.x + dp1perp * duv2.x;
    vec3 b = dp2perp * duv1.y + dp1perp * duv2.y;
    float scale = max(dot(t, t), dot(b, b));
    if (scale <= 0.0) return n;  // degenerate UVs (e.g. seen edge-on): keep the mesh normal
    float inv = inversesqrt(scale);
    vec3 m = texture(u_normal_map, v_uv).xyz * 2.0 - 1.0;
    return normalize(mat3(t * inv, b * inv, n) * m);
}

float sun_visibility(vec3 n) {
    if (!u_has_shadows) return 1.0;
    vec4 p = u_shadow_from_view * vec4(v_view_pos + n * u_shadow_offset_m, 1.0);
    // Outside the shadowed range (beyond shadow_distance_m): lit.
    if (any(lessThan(p.xyz, vec3(0.0))) || any(greaterThan(p.xyz, vec3(1.0)))) return 1.0;
    float lit = 0.0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
            lit += texture(u_shadow_map, vec3(p.xy + vec2(dx, dy) * u_shadow_texel, p.z));
    return lit / 9.0;
}

void main() {
    vec3 view_dir = normalize(-v_view_pos);
    vec3 n = normalize(v_normal);
    if (dot(n, view_dir) < 0.0) n = -n;  // two-sided: open sheets (ground, panels)
    float sun = sun_visibility(n);       // by the mesh normal: the normal map only shades
    if (u_has_normal_map) n = perturbed_normal(n, view_dir);

    vec4 base = u_base_color * vec4(srgb_to_linear(texture(u_base_color_map, v_uv).rgb), 1.0);
    vec3 mr = texture(u_metallic_roughness_map, v_uv).rgb;
    float metallic = clamp(u_metallic * mr.b, 0.0, 1.0);
    float roughness = clamp(u_roughness * mr.g, 0.04, 1.0);
    float alpha = roughness * roughness;

    vec3 f0 = mix(vec3(0.04), base.rgb, metallic);
    vec3 l = normalize(u_sun_dir);
    vec3 h = normalize(l + view_dir);
    float nl = max(dot(n, l), 0.0), nv = max(dot(n, view_dir), 1e-4);
    float nh = max(dot(n, h), 0.0), vh = max(dot(view_dir, h), 0.0);

    float a2 = alpha * alpha;
    float denom = nh * nh * (a2 - 1.0) + 1.0;
    float D = a2 / (PI * denom * denom);
    float k = (roughness + 1.0) * (roughness + 1.0) / 8.0;
    float G = (nl / (nl * (1.0 - k) + k)) * (nv / (nv * (1.0 - k) + k));
    vec3 F = f0 + (1.0 - f0) * pow(1.0 - vh, 5.0);
    vec3 specular = D * G * F / max(4.0 * nl * nv, 1e-4);
    vec3 diffuse = (1.0 - F) * (1.0 - metallic) * base.rgb / PI;
    vec3 direct = (diffuse + specular) * u_sun_color * nl * sun;

    // Hemisphere ambient: diffuse by the normal, specular by the reflected direction.
    float up_n = dot(n, u_up) * 0.5 + 0.5;
    float up_r = dot(reflect(-view_dir, n), u_up) * 0.5 + 0.5;
    vec3 env_diffuse = mix(u_ground_color, u_sky_color, up_n);
    vec3 env_specular = mix(u_ground_color, u_sky_color, up_r);
    vec3 f_env = f0 + (max(vec3(1.0 - roughness), f0) - f0) * pow(1.0 - nv, 5.0);
    vec3 ambient = (1.0 - metallic) * base.rgb * env_diffuse
                 + f_env * env_specular * (1.0 - 0.7 * roughness);

    vec3 emissive = u_emissive * srgb_to_linear(texture(u_emissive_map, v_uv).rgb);
    f_color = vec4(tone_map((direct + ambient) * u_exposure + emissive), 1.0);
}
