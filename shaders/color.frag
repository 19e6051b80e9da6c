#version 330 core
// Metallic-roughness PBR: GGX specular + Burley diffuse under one sun, plus ambient light
// from the sky and the ground (spherical-harmonic irradiance, glsynth.world.lighting; the
// lighting functions are in lighting.glsl, where tests/test_lighting_shader.py tests them),
// occluded by the sky-visibility maps and optionally screen-space ambient occlusion, plus
// emission (scene panels are emission-only). The normal map (the damage normal map on damaged
// columns) perturbs the normal in a tangent frame built from screen-space derivatives of
// position and UV, so meshes need no tangent attribute. The sun is shadowed by a shadow map
// (3x3 percentage-closer filtering) where u_has_shadows is set. Drawn against the label pass's
// depth, so each visible pixel is shaded once; under MSAA the shading normal goes to a second
// target, for msaa.frag. The crack variant (#define CRACKS) darkens the reflected light by the
// share of the pixel that the part's cracks cover (from the label pass, which drew this very
// surface at this pixel), times u_crack_contrast, and draws what leaching cracks leave on the
// concrete (crack_leachate.glsl: efflorescence, rust, damp). The zone variant (#define SPALL) shows the
// damage material only inside the part's zones and there only where the damage mask is
// spalled or rebar (the filtered share u_spall_map), the intact concrete u_intact_map
// elsewhere: no metal, no relief outside the zones. The detail variant (#define DETAIL)
// multiplies the base colour by concrete's millimetre-scale detail (concrete_detail.glsl),
// on the non-metallic share of the surface (not on exposed rebar), weathered (weathering.glsl)
// where u_weathering is set. The ground's variant (#define GROUND, with DETAIL) draws the
// ground's centimetre detail (ground_detail.glsl) from the base colour instead.
in vec3 v_view_pos;
in vec3 v_normal;
in vec2 v_uv;

uniform vec4 u_base_color;
uniform float u_metallic;
uniform float u_roughness;
uniform vec3 u_emissive;
uniform sampler2D u_base_color_map;          // RGB sRGB colour, A metallic; 1x1 white if none
uniform sampler2D u_emissive_map;            // sRGB; 1x1 white if none
uniform sampler2D u_normal_map;              // tangent space, 1x1 (0.5, 0.5, 1) if none
uniform bool u_has_normal_map;

// Sky visibility, from the half-resolution pass (sky_visibility.frag): u_vis_count > 0.
uniform int u_vis_count;                // 0: no sky occlusion
uniform sampler2D u_sky_light;          // (hidden irradiance rgb, visibility by the normal)
uniform sampler2D u_sky_surface;        // (shading normal, linear depth)
uniform sampler2D u_sky_open;           // mean visibility over all directions
uniform vec3 u_exposure;  // per channel: the exposure times the white balance

uniform bool u_has_shadows;
uniform sampler2DShadow u_shadow_map;
uniform mat4 u_shadow_from_view;   // shadow-map texture coordinates and depth, all in [0, 1]
uniform float u_shadow_texel;      // 1 / map size
uniform float u_shadow_offset_m;   // lookups move this far along the normal (against acne)

layout(location = 0) out vec4 f_color;
layout(location = 1) out vec4 f_normal;  // the shading normal, for msaa.frag

#ifdef CRACKS
in vec3 v_crack_pos;  // mesh frame, relative to the crack grid's origin (mesh.vert)
uniform sampler2D u_crack;       // the label pass's (crack width mm, coverage) per pixel
uniform float u_crack_contrast;  // the share of the reflected light a crack's cavity takes away
#include "cracks.glsl"
#include "crack_leachate.glsl"
// Leachate on the concrete's colour (docs/design.md, "Cracks"): calcite's linear albedo, the
// factor that rust's iron oxides dye concrete by, and the share of its light damp takes.
const vec3 EFFLORESCENCE_ALBEDO = vec3(0.70, 0.70, 0.67);
const vec3 RUST_DYE = vec3(0.78, 0.36, 0.14);
const float DAMP_DARKENING = 0.3;
#endif

#ifdef SPALL
in vec3 v_mesh_pos;
uniform sampler2D u_intact_map;   // sRGB: the part's own concrete
uniform sampler2D u_spall_map;    // R: 1 where the damage mask is 2 or 3, filtered
uniform float u_intact_uv_ratio;  // the intact map's uv_scale over the damage material's
#include "zones.glsl"
#endif

#ifdef DETAIL
in vec3 v_detail_pos;
in vec3 v_detail_normal;
uniform uint u_detail_seed;
#ifdef GROUND
#include "ground_detail.glsl"
#else
uniform bool u_weathering;    // weathering.glsl on top of the detail
uniform vec3 u_detail_tint;   // linear factor: the part's weathered albedo over its image's
uniform float u_detail_top;   // the part's box's height, mesh frame (where rain runs from)
#include "weathering.glsl"
#endif
#endif

#include "tonemap.glsl"
#include "facing_normal.glsl"
#include "lighting.glsl"

// (sky visibility seen by normal n, mean visibility over all directions) and, in ``hidden``,
// the irradiance from the emitting parts that hide the sky: the half-resolution pass's
// values at the four texels around this pixel, bilinearly weighted, of those on this
// fragment's surface (the same normal, and a depth this surface can reach that far away);
// where none is, the nearest match. No branch depends on the lane (see msaa.frag).
vec2 sky_visibility(vec3 n, out vec3 hidden) {
    hidden = vec3(0.0);
    if (u_vis_count == 0) return vec2(1.0);
    vec2 u = gl_FragCoord.xy * 0.5 - 0.5;  // in half-resolution texels
    ivec2 base = ivec2(floor(u)), last = textureSize(u_sky_light, 0) - 1;
    vec2 f = u - vec2(base);
    float depth = -v_view_pos.z;
    // A texel centre lies at most 1.5 pixels away in each direction.
    float reach = 2.0 * (abs(dFdx(depth)) + abs(dFdy(depth))) + 1e-4 * depth;
    vec4 light = vec4(0.0), best_light = vec4(0.0);
    float open = 0.0, best_open = 0.0, weights = 0.0, best_cost = 1e30;
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 q = clamp(base + o, ivec2(0), last);
        vec4 surface = texelFetch(u_sky_surface, q, 0);  // 0 where no part was drawn
        vec4 texel_light = texelFetch(u_sky_light, q, 0);
        float texel_open = texelFetch(u_sky_open, q, 0).r;
        float cosine = dot(surface.xyz, n), gap = abs(surface.w - depth);
        float w = (o.x == 1 ? f.x : 1.0 - f.x) * (o.y == 1 ? f.y : 1.0 - f.y)
                  * float(cosine > 0.99 && gap <= reach);
        light += w * texel_light;
        open += w * texel_open;
        weights += w;
        float cost = 1.0 - cosine + gap / depth;
        best_light = cost < best_cost ? texel_light : best_light;
        best_open = cost < best_cost ? texel_open : best_open;
        best_cost = min(cost, best_cost);
    }
    bool matched = weights > 1e-6;
    light = matched ? light / weights : best_light;
    hidden = light.rgb;
    return vec2(light.a, matched ? open / weights : best_open);
}

vec3 perturbed_normal(vec3 n) {
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

// The surface's material at this fragment (lighting.glsl's Surface).
Surface surface_at_fragment() {
    vec4 texel = texture(u_base_color_map, v_uv);
    vec4 base = u_base_color * vec4(srgb_to_linear(texel.rgb), 1.0);
    float metallic = clamp(u_metallic * texel.a, 0.0, 1.0);
#ifdef SPALL
    // Looked up everywhere and selected after: derivatives need uniform control flow.
    float spalled = texture(u_spall_map, v_uv).r * float(in_zones(v_mesh_pos.z));
    vec3 intact = srgb_to_linear(texture(u_intact_map, v_uv * u_intact_uv_ratio).rgb);
    base.rgb = mix(intact, base.rgb, spalled);
    metallic *= spalled;
#endif
#if defined(GROUND)
    base.rgb = ground_detail(base.rgb, v_detail_pos, u_detail_seed);
#elif defined(DETAIL)
    if (u_weathering) {
        base.rgb *= mix(weathered_concrete(v_detail_pos, v_detail_normal, u_detail_seed,
                                           u_detail_top) * u_detail_tint, vec3(1.0), metallic);
    } else {
        base.rgb *= mix(concrete_detail(v_detail_pos, v_detail_normal, u_detail_seed), 1.0,
                        metallic);
    }
#endif
#ifdef CRACKS
    // Derivatives here, in uniform control flow; on the concrete, not on exposed bars.
    vec3 dpdx = dFdx(v_crack_pos), dpdy = dFdy(v_crack_pos);
    vec3 leach = leachate_at(v_crack_pos, crack_normal(dpdx, dpdy), length(dpdx) + length(dpdy))
        * (1.0 - metallic);
    base.rgb = mix(base.rgb, EFFLORESCENCE_ALBEDO, leach.x);
    base.rgb *= mix(vec3(1.0), RUST_DYE, leach.y) * (1.0 - DAMP_DARKENING * leach.z);
#endif
    return Surface(base.rgb, metallic, clamp(u_roughness, 0.04, 1.0),
                   mix(vec3(0.04), base.rgb, metallic));
}

void main() {
    vec3 view_dir = normalize(-v_view_pos);
    vec3 n = facing_normal(v_normal, view_dir);
    f_normal = vec4(n, 1.0);
    float sun = sun_visibility(n);       // by the mesh normal: the normal map only shades
    vec3 hidden;
    vec2 vis = sky_visibility(n, hidden);
#ifdef SPALL
    if (u_has_normal_map) {
        vec3 relief = perturbed_normal(n);
        n = in_zones(v_mesh_pos.z) ? relief : n;
    }
#else
    if (u_has_normal_map) n = perturbed_normal(n);
#endif
    Surface s = surface_at_fragment();
    vec3 direct = sun_light(s, n, view_dir) * sun;
    vec3 ambient = ambient_light(s, n, view_dir, vis, hidden);
#ifdef CRACKS
    float dark = 1.0 - u_crack_contrast * texelFetch(u_crack, ivec2(gl_FragCoord.xy), 0).g;
    direct *= dark;
    ambient *= dark;
#endif
    vec3 emissive = u_emissive * srgb_to_linear(texture(u_emissive_map, v_uv).rgb);
    f_color = vec4(tone_map((direct + ambient + emissive) * u_exposure), 1.0);
}
