#version 330 core
// The sky visibility of the surface seen at every second pixel in each direction (a target of
// half the image's width and height), for the colour pass to upsample by surface
// (color.frag): visibility varies slowly over a surface, and its 16 shadow-map lookups were
// half of the colour pass's cost at every pixel.
in vec3 v_view_pos;
in vec3 v_normal;

// Sky visibility: depth maps of the scene seen from u_vis_count sky directions, tiled in one
// atlas (drawn once per environment). A direction is visible where the point is not behind
// the map's depth; its weight is the sky's luminance there times the cosine to the normal.
uniform int u_vis_count;                // 0: no sky occlusion
uniform sampler2DShadow u_vis_map;
// MAX_VIS (#defined by glsynth.render.gl.programs): the most maps a config may ask for.
uniform mat4 u_vis_from_view[MAX_VIS];  // atlas coordinates and depth from camera space
uniform vec3 u_vis_dir[MAX_VIS];        // camera space, towards the sky
uniform float u_vis_weight[MAX_VIS];
uniform float u_vis_offset_m;
// Where a direction is hidden, the light of what hides it: the emitted radiance of the first
// part seen from the sky along that direction (scene panels), in the same atlas layout, stored
// over the scene's brightest part.
uniform sampler2D u_vis_radiance;
uniform float u_vis_solid_angle;        // each direction's solid angle x that brightest radiance

layout(location = 0) out vec4 f_light;    // (hidden irradiance rgb, visibility by the normal)
layout(location = 1) out vec4 f_surface;  // (shading normal, linear depth)
layout(location = 2) out vec4 f_open;     // (mean visibility over all directions, 0, 0, 0)

#include "facing_normal.glsl"

// (sky visibility seen by normal n, mean visibility over all directions); ``hidden`` gets
// the irradiance from the emitting parts that hide the sky.
vec2 sky_visibility(vec3 n, out vec3 hidden) {
    hidden = vec3(0.0);
    if (u_vis_count == 0) return vec2(1.0);
    float weighted = 0.0, total = 0.0, mean = 0.0;
    int tiles = int(round(sqrt(float(u_vis_count))));  // the atlas is square
    // Map k's tile, (k % tiles, k / tiles), counted along: llvmpipe divides integers one lane
    // at a time.
    ivec2 tile = ivec2(0);
    for (int k = 0; k < u_vis_count; ++k) {
        vec4 p = u_vis_from_view[k] * vec4(v_view_pos + n * u_vis_offset_m, 1.0);
        // A point outside its map (the far terrain, to which the maps are not fitted) would
        // read a neighbouring map: it counts as open to the sky.
        vec2 lo = vec2(tile) / float(tiles);
        bool inside = all(greaterThanEqual(p.xy, lo)) && all(lessThan(p.xy, lo + 1.0 / float(tiles)))
                      && p.z < 1.0;
        float v = inside ? texture(u_vis_map, p.xyz) : 1.0;
        float c = max(dot(n, u_vis_dir[k]), 0.0);
        float w = u_vis_weight[k] * c;
        weighted += w * v;
        total += w;
        mean += v;
        hidden += (1.0 - v) * c * texture(u_vis_radiance, p.xy).rgb;
        tile = tile.x + 1 < tiles ? ivec2(tile.x + 1, tile.y) : ivec2(0, tile.y + 1);
    }
    mean /= float(u_vis_count);
    hidden *= u_vis_solid_angle;
    return vec2(total > 0.0 ? weighted / total : mean, mean);
}

void main() {
    vec3 n = facing_normal(v_normal, normalize(-v_view_pos));
    vec3 hidden;
    vec2 vis = sky_visibility(n, hidden);
    f_light = vec4(hidden, vis.x);
    f_surface = vec4(n, -v_view_pos.z);
    f_open = vec4(vis.y, 0.0, 0.0, 0.0);
}
