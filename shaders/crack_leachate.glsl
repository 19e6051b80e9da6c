// What runs out of a leaching crack, for the colour pass (colour only: the label pass never
// reads it). glsynth.render.leachate_index packs the leaching cracks' segments and a grid over
// the regions they reach; a fragment reads its own cell's list (one list, no neighbours: a
// segment is listed in every cell its region meets). docs/design.md, "Cracks", gives the rules.
// LEACH_* constants are macros from glsynth.appearance.crack_leachate. Needs cracks.glsl (the
// crack's path: the deposit and the damp follow the crack as drawn, not its chord).
// Its textures are rows of cracks_index.ROW texels, as the crack textures: crack_texel reads both.
uniform sampler2D u_leach_items;     // RGBA32F, 4 texels per segment (leachate_index)
uniform isampler2D u_leach_cells;    // (first entry, count) per cell
uniform isampler2D u_leach_entries;  // segment ids, cell after cell
uniform vec3 u_leach_origin;         // the grid's corner, relative to the crack grid's
uniform float u_leach_cell_m;
uniform ivec3 u_leach_dims;
uniform bool u_has_leach;            // the part has leaching cracks

// Value noise in [0, 1] along one coordinate (a lowbias32 hash per integer).
float leach_noise(float x) {
    float i = floor(x), f = x - i;
    uint k = uint(int(i) + 1048576);
    uint h0 = k * 0x9e3779b9u, h1 = (k + 1u) * 0x9e3779b9u;
    h0 ^= h0 >> 16u; h0 *= 0x7feb352du; h0 ^= h0 >> 15u; h0 *= 0x846ca68bu; h0 ^= h0 >> 16u;
    h1 ^= h1 >> 16u; h1 *= 0x7feb352du; h1 ^= h1 >> 15u; h1 *= 0x846ca68bu; h1 ^= h1 >> 16u;
    return mix(float(h0 >> 8u), float(h1 >> 8u), f * f * (3.0 - 2.0 * f)) / 16777216.0;
}

// The leaching segment whose middle is nearest to p in cell list ``list`` (one texel each),
// and its parameter at p: (id, t); id -1 where the list is empty.
vec2 leach_nearest(ivec2 list, vec3 p) {
    float best = 1e30;
    int id = -1;
    for (int k = 0; k < list.y; ++k) {
        int s = texelFetch(u_leach_entries, crack_texel(list.x + k), 0).r;
        vec3 m = texelFetch(u_leach_items, crack_texel(4 * s + 3), 0).xyz;
        float d = distance(p, m);
        id = d < best ? s : id;
        best = min(d, best);
    }
    if (id < 0) return vec2(-1.0, 0.0);
    vec3 a = texelFetch(u_leach_items, crack_texel(4 * id), 0).xyz;
    vec3 b = texelFetch(u_leach_items, crack_texel(4 * id + 1), 0).xyz;
    return vec2(float(id), segment_param(p, a, b));
}

// p moved across the nearest leaching crack by that crack's path offset there (the crack
// texture's segment, cracks.glsl's crack_offset to ``finest_m``), so that what follows is
// measured from the crack as drawn.
vec3 leach_on_path(vec3 p, vec2 nearest, vec3 normal, float finest_m) {
    if (!u_crack_rough || nearest.x < 0.0) return p;
    int segment = int(texelFetch(u_leach_items, crack_texel(4 * int(nearest.x) + 2),
                                 0).z);
    vec4 a = texelFetch(u_crack_segments, crack_texel(2 * segment), 0);
    vec4 b = texelFetch(u_crack_segments, crack_texel(2 * segment + 1), 0);
    vec3 ab = b.xyz - a.xyz, across = cross(normal, ab);
    if (!(dot(across, across) > 0.0)) return p;
    uint seed = crack_hash(floatBitsToUint(a.w) ^ crack_hash(floatBitsToUint(b.w)));
    return p - normalize(across) * crack_offset(nearest.y, length(ab), seed, finest_m).x;
}

// (efflorescence, rust, damp), each 0-1, at p (relative to the crack grid's corner) on a
// surface whose mesh-frame normal is ``normal`` (crack_normal), seen through a pixel whose
// footprint is ``size`` (m). Below each leaching segment its deposit runs down (mesh -z) as
// rivulets up to the run's length, varying along the crack at 2 cm and streaked at 7 mm,
// fading as it runs and spreading by LEACH_SPREAD per metre beyond the crack's ends; a face
// that looks up or down gets no run. At the crack the deposit crusts the mouth, half the damp
// band's reach either side, and the damp band darkens either side.
vec3 leachate_at(vec3 p, vec3 normal, float size) {
    vec3 leach = vec3(0.0);
    if (!u_has_leach) return leach;
    ivec3 c = ivec3(floor((p - u_leach_origin) / u_leach_cell_m));
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, u_leach_dims))) return leach;
    int cell = c.x + u_leach_dims.x * (c.y + u_leach_dims.y * c.z);
    ivec2 list = texelFetch(u_leach_cells, crack_texel(cell), 0).xy;
    p = leach_on_path(p, leach_nearest(list, p), normal,
                      max(size, LEACH_PATH_M));
    float runs = 1.0 - smoothstep(0.5, 0.9, abs(normal.z) / max(length(normal), 1e-20));
    for (int k = 0; k < list.y; ++k) {
        int s = texelFetch(u_leach_entries, crack_texel(list.x + k), 0).r;
        vec4 a = texelFetch(u_leach_items, crack_texel(4 * s), 0);
        vec4 b = texelFetch(u_leach_items, crack_texel(4 * s + 1), 0);
        vec4 e = texelFetch(u_leach_items, crack_texel(4 * s + 2), 0);
        vec3 ab = b.xyz - a.xyz;
        float level = dot(ab.xy, ab.xy);
        // The crack's point above p: by the horizontal position (a vertical segment: its foot).
        float t = level > 1e-12 ? clamp(dot(p.xy - a.xy, ab.xy) / level, 0.0, 1.0)
                                : float(ab.z < 0.0);
        vec3 q = a.xyz + ab * t;
        float drop = q.z - p.z, side = length(p.xy - q.xy);
        float u = t * sqrt(level) + e.y;
        float reach = b.w * (0.2 + 0.8 * leach_noise(u / 0.02));
        float spread = LEACH_SPREAD0_M + LEACH_SPREAD * max(drop, 0.0);
        float fade = max(1.0 - drop / reach, 0.0);
        float run = drop > 0.0 ? fade * fade : 0.0;
        run *= (1.0 - smoothstep(0.5 * spread, spread, side)) * runs
            * (0.3 + 0.7 * smoothstep(0.3, 0.7, leach_noise(u / 0.007 + 17.0)));
        float d = distance(p, a.xyz + ab * segment_param(p, a.xyz, b.xyz));
        float mouth = 1.0 - smoothstep(0.15 * e.x, 0.5 * e.x, d);
        float deposit = abs(a.w) * max(0.8 * run, mouth);
        leach.x = max(leach.x, a.w > 0.0 ? deposit : 0.0);
        leach.y = max(leach.y, a.w < 0.0 ? deposit : 0.0);
        leach.z = max(leach.z, 1.0 - smoothstep(0.3 * e.x, e.x, d));
    }
    return leach;
}
