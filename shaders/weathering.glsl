// Weathered concrete (docs/design.md, "Weathered concrete"): concrete detail (the included
// concrete_detail.glsl) under the marks that years of rain and sun leave on a member, placed by
// where water runs and collects, as a factor (linear RGB) on the base colour:
// - mottling: the cement paste's colour varying over 0.1-2 m (mix water, curing, soiling);
// - water streaks: rain running down from the face's top edge carries dirt down in narrow
//   wandering streaks that fade towards their lower end;
// - rust streaks below a share of the formwork's tie holes (a steel tie end rusting);
// - efflorescence: white salt blooms where water seeps out of a horizontal formwork joint,
//   below the joint;
// - dirt: soiled blotches, more of them on faces that look up (dust settles, water stands);
// - patch repairs: a rectangle of newer mortar, lighter and smoother, with a dark edge;
// - damp: wet concrete, darker, at the foot of a face and below leaking formwork joints, each
//   behind a sharp drying front; algae in patches on a share of the damp feet and leaks.
// Vertical faces (normal's dominant axis horizontal) get streaks, blooms and damp; every face
// the rest. Deterministic: a function of the position, the normal and the part's seed alone.
#include "concrete_detail.glsl"

// Value noise over octaves from size_m down, each amp times the last's amplitude, faded to
// its mean where a pixel's footprint nears the octave's size; in about [-1, 1] x the sum.
float octaves(vec2 p, float size_m, int count, float amp, float footprint, uint salt) {
    float sum = 0.0, a = 1.0;
    for (int k = 0; k < count; ++k) {
        sum += a * resolved(size_m, footprint) * value_noise(p / size_m, salt + uint(k));
        size_m *= 0.5;
        a *= amp;
    }
    return sum;
}

// Rain streaks from the top edge (p.y = top_m): the face cut into columns 6 cm wide; in
// 45 % of them a streak of log-uniform length 0.3-4 m and half-width 4-25 mm, whose darkness
// falls linearly to nothing at its lower end. Its path wanders by up to 3 cm.
float rain_streaks(vec2 p, float top_m, float footprint, uint salt) {
    float below = top_m - p.y;
    float u = p.x + 0.03 * value_noise(vec2(p.x / 0.5, p.y / 0.7), salt ^ 21u);
    float column = floor(u / 0.06);
    uint h = cell_hash(ivec2(int(column), 0), salt ^ 22u);
    float length_m = 0.3 * pow(4.0 / 0.3, unit_float(detail_hash(h)));
    float darkness = 0.10 + 0.30 * unit_float(detail_hash(h ^ 1u));
    float half_width = 0.004 + 0.021 * unit_float(detail_hash(h ^ 2u));
    float across = abs(u - (column + 0.5) * 0.06);
    float profile = 1.0 - smoothstep(0.3 * half_width, half_width + footprint, across);
    float along = clamp(1.0 - below / length_m, 0.0, 1.0) * float(below >= 0.0);
    float patchy = 0.75 + 0.25 * value_noise(vec2(u / 0.02, p.y / 0.15), salt ^ 23u);
    return float(unit_float(h) < 0.45) * darkness * profile * along * patchy;
}

// Rust below the tie holes of formwork(): a share of 20 % of the holes each bleed a streak
// 5-60 cm long and 3-10 mm wide down from the hole. A streak may pass into the two cells
// below its hole's, so each fragment looks at its own cell's hole and the two above.
float rust_streaks(vec2 p, vec2 offset, float footprint, uint salt) {
    vec2 q = p / 0.6 + offset;
    float rust = 0.0;
    for (int j = 0; j < 3; ++j) {
        ivec2 cell = ivec2(floor(q)) + ivec2(0, j);
        vec2 hole = (vec2(cell) + 0.5 - offset) * 0.6;  // its centre, face metres
        uint h = cell_hash(cell, salt ^ 31u);
        float length_m = 0.05 + 0.55 * unit_float(detail_hash(h));
        float half_width = 0.003 + 0.007 * unit_float(detail_hash(h ^ 1u));
        float below = hole.y - p.y;
        float width = half_width * (1.0 + 0.6 * below / length_m);  // it spreads as it runs
        float profile = 1.0 - smoothstep(0.4 * width, width + footprint, abs(p.x - hole.x));
        float along = clamp(1.0 - below / length_m, 0.0, 1.0) * float(below >= 0.0125);
        rust = max(rust, float(unit_float(h) < 0.2) * profile * along);
    }
    return rust;
}

// The horizontal formwork joint above p (one every 2.44 m), cut into stretches 0.8 m long:
// how far below it p lies, and p's stretch (its index along the face, and its hash).
float below_joint(vec2 p, vec2 offset, uint salt, out float cell, out uint h) {
    float row = floor(p.y / FORMWORK_PANEL_M.y + offset.y) + 1.0;
    cell = floor(p.x / 0.8);
    h = cell_hash(ivec2(int(cell), int(row)), salt);
    return (row - offset.y) * FORMWORK_PANEL_M.y - p.y;
}

// Efflorescence below the horizontal joints of formwork() (every 2.44 m): the joint cut into
// cells 0.8 m long, in 25 % of them a bloom 0.1-0.5 m wide reaching 5-40 cm down, its edge
// frayed by noise; its whiteness fades downwards.
float efflorescence(vec2 p, vec2 offset, float footprint, uint salt) {
    float cell;
    uint h;
    float below = below_joint(p, offset, salt ^ 41u, cell, h);
    float centre = (cell + 0.2 + 0.6 * unit_float(detail_hash(h))) * 0.8;
    float half_width = 0.05 + 0.20 * unit_float(detail_hash(h ^ 1u));
    float depth = 0.05 + 0.35 * unit_float(detail_hash(h ^ 2u));
    vec2 d = vec2((p.x - centre) / half_width, below / depth);
    float fray = 0.25 * value_noise(p / 0.03, salt ^ 42u);
    float inside = 1.0 - smoothstep(1.0 - footprint / depth, 1.0, length(d) + fray);
    return float(unit_float(h) < 0.25) * inside * (1.0 - 0.7 * clamp(d.y, 0.0, 1.0));
}

// Patch repairs: cells of 1.6 m, in 12 % of them a rectangle 0.16-0.7 x 0.12-0.5 m with
// rounded corners and an edge frayed by 5 mm, anywhere inside its cell. 1 inside, 0 out;
// ``edge`` the share of the pixel on its 3 mm outline.
float patch_repair(vec2 p, float footprint, uint salt, out float edge) {
    vec2 cell = floor(p / 1.6);
    uint h = cell_hash(ivec2(cell), salt ^ 51u);
    vec2 half_size = vec2(0.08 + 0.27 * unit_float(detail_hash(h)),
                          0.06 + 0.19 * unit_float(detail_hash(h ^ 1u)));
    vec2 room = 0.8 - half_size;
    vec2 centre = (cell + 0.5) * 1.6 + room * (2.0 * vec2(unit_float(detail_hash(h ^ 2u)),
                                                          unit_float(detail_hash(h ^ 3u))) - 1.0);
    vec2 d = abs(p - centre) - half_size + 0.02;
    float outside = length(max(d, 0.0)) + min(max(d.x, d.y), 0.0) - 0.02
                    + 0.005 * value_noise(p / 0.02, salt ^ 52u);  // signed distance, metres
    float present = float(unit_float(h) < 0.12);
    edge = present * clamp((0.0015 + 0.5 * footprint - abs(outside)) / footprint, 0.0, 1.0)
           * resolved(0.003, footprint);
    return present * clamp(0.5 - outside / footprint, 0.0, 1.0);
}

// The share of a pixel of footprint fp inside a region whose boundary lies ``inside_m`` metres
// away (positive inside): a step at the pixel, as a drying front is a step in wetness.
float sharp_inside(float inside_m, float fp) {
    return clamp(inside_m / fp + 0.5, 0.0, 1.0);
}

// Damp: water in the surface pores takes the place of air, so wet concrete scatters back
// less light and looks darker until it dries; a drying front stays sharp. damp_foot and
// damp_leak each give the share of the colour they take away, on vertical faces.
// The damp fronts' raggedness at 2 cm, metres.
float fray_m(vec2 p, float footprint, uint salt) {
    return 0.012 * resolved(0.02, footprint) * value_noise(p / 0.02, salt ^ 73u);
}

// The foot of the part's box, on 40 % of faces: splash and water drawn up from below (on a
// beam or a slab's edge, water run round from the soffit), up to a front 0.1-0.8 m high that
// wanders up to +-30 % along the face over 0.5 m. How far below that front p lies (metres,
// negative above it), and the foot's hash.
float below_front(vec2 p, float footprint, uint salt, out uint h) {
    h = detail_hash(salt ^ 71u);
    float height = (0.1 + 0.7 * unit_float(detail_hash(h ^ 1u)))
                   * (1.0 + 0.3 * value_noise(vec2(p.x / 0.5, 0.5), salt ^ 72u));
    return height + fray_m(p, footprint, salt) - p.y;
}

// A damp foot: 20-40 % darker up to its front, with a tide line 2-6 mm wide along the front
// (the dirt and salt the water leaves where it evaporates), darker again.
float damp_foot(vec2 p, float footprint, uint salt) {
    uint h;
    float under = below_front(p, footprint, salt, h);
    float tide_half = 0.001 + 0.002 * unit_float(detail_hash(h ^ 3u));
    float tide = sharp_inside(tide_half - abs(under), footprint)
                 * min(1.0, 2.0 * tide_half / footprint);
    float darkness = float(unit_float(h) < 0.4) * float(p.y >= 0.0)
                     * (0.20 + 0.20 * unit_float(detail_hash(h ^ 2u)));
    return darkness * max(sharp_inside(under, footprint), 1.5 * tide);
}

// Algae: green algae and cyanobacteria colonise concrete that stays wet, so on 60 % of the
// damp feet and of the leaks a film grows in patches (noise over 0.2 m down to 5 cm passing a
// threshold), covering most of the concrete where the water comes from (the ground; the
// joint) and thinning out to a few specks towards the front or the tip, its edge soft (a film
// that thins out, not a front). algae_film: the share of the pixel it covers, 0-1, given how
// near the source p lies (1 at it, 0 at the wet region's far end).
float algae_film(vec2 p, float near_source, float footprint, uint salt) {
    float patches = 0.5 + 0.3 * octaves(p, 0.2, 3, 0.5, footprint, salt ^ 76u);
    return smoothstep(0.75 - 0.5 * near_source, 0.9 - 0.5 * near_source, patches);
}

float algae(vec2 p, float footprint, uint salt) {
    uint h;
    float under = below_front(p, footprint, salt, h);
    // 1 at the ground, 0 at the front.
    float low = clamp(under / max(under + p.y, 1e-3), 0.0, 1.0);
    float present = float(unit_float(h) < 0.4) * float(unit_float(detail_hash(h ^ 4u)) < 0.6)
                    * float(p.y >= 0.0);
    return present * algae_film(p, low, footprint, salt) * sharp_inside(under, footprint);
}

// Algae's factor on the colour where its film covers the concrete, drawn per face (its foot and
// leaks alike) between green (chlorophyll absorbs red and blue) and the grey-black of
// cyanobacteria: 31-56 % darker in luminance.
vec3 algae_tint(uint salt) {
    float t = unit_float(detail_hash(detail_hash(salt ^ 71u) ^ 5u));
    return mix(vec3(0.60, 0.74, 0.48), vec3(0.42, 0.45, 0.40), t);
}

// A leak below 12 % of the 0.8 m stretches of each horizontal formwork joint: a wet tongue
// 0.1-0.4 m wide running 0.2-1.5 m down, 15-35 % darker, frayed like the foot's front. Its
// edge is a step at the pixel all round: the distance to the ellipse, in metres, is taken to
// first order ((1 - r) over r's gradient), true across the tongue and at its tip alike.
// leak_inside: that distance (negative outside), how far down the tongue p lies (0 at the
// joint, 1 at the tip) and the stretch's hash.
float leak_inside(vec2 p, vec2 offset, float footprint, uint salt, out float down, out uint k) {
    float cell;
    float below = below_joint(p, offset, salt ^ 74u, cell, k);
    float centre = (cell + 0.25 + 0.5 * unit_float(detail_hash(k))) * 0.8;
    float half_width = 0.05 + 0.15 * unit_float(detail_hash(k ^ 1u));
    float length_m = 0.2 + 1.3 * unit_float(detail_hash(k ^ 2u));
    vec2 d = vec2((p.x - centre) / half_width, below / length_m);
    float r = length(d);
    vec2 gradient = vec2(d.x / half_width, d.y / length_m) / max(r, 1e-6);  // of r, per metre
    down = clamp(d.y, 0.0, 1.0);
    return (1.0 - r) / max(length(gradient), 1e-6) + fray_m(p, footprint, salt);
}

float damp_leak(vec2 p, vec2 offset, float footprint, uint salt) {
    float down;
    uint k;
    float inside_m = leak_inside(p, offset, footprint, salt, down, k);
    return float(unit_float(k) < 0.12) * (0.15 + 0.20 * unit_float(detail_hash(k ^ 3u)))
           * sharp_inside(inside_m, footprint);
}

// Algae in a leak's tongue, on 60 % of the leaks (algae).
float leak_algae(vec2 p, vec2 offset, float footprint, uint salt) {
    float down;
    uint k;
    float inside_m = leak_inside(p, offset, footprint, salt, down, k);
    float present = float(unit_float(k) < 0.12) * float(unit_float(detail_hash(k ^ 4u)) < 0.6);
    return present * algae_film(p, 1.0 - down, footprint, salt) * sharp_inside(inside_m, footprint);
}

// Weathered concrete's factor on the base colour at mesh-frame position pos (relative to the
// part's box's lower corner, z up), normal n (mesh frame), for part seed, on a part whose box
// is top_m high: concrete_detail() times the weathering.
vec3 weathered_concrete(vec3 pos, vec3 n, uint seed, float top_m) {
    vec2 p;
    uint salt;
    int axis = detail_face(pos, n, seed, p, salt);
    float footprint = max(max(length(dFdx(pos)), length(dFdy(pos))), 1e-6);
    float detail = concrete_detail(pos, n, seed);
    vec2 offset = formwork_offset(salt);
    bool vertical = axis != 2;
    float mottle = 0.16 * octaves(p, 2.0, 5, 0.65, footprint, salt ^ 61u);
    float hue = 0.03 * octaves(p, 1.0, 2, 0.5, footprint, salt ^ 62u);
    // Dirt: blotches where noise at 0.6 m passes a threshold; faces looking up hold more.
    float up = float(axis == 2 && n.z > 0.0);
    float blotch = smoothstep(0.25 - 0.35 * up, 0.7, value_noise(p / 0.6, salt ^ 63u))
                   * resolved(0.1, footprint);
    float dirt = (0.18 + 0.12 * up) * blotch;
    float rain = vertical ? rain_streaks(p, top_m, footprint, salt) : 0.0;
    float rust = vertical ? rust_streaks(p, offset, footprint, salt) : 0.0;
    float bloom = vertical ? efflorescence(p, offset, footprint, salt) : 0.0;
    float wet = vertical ? max(damp_foot(p, footprint, salt),
                               damp_leak(p, offset, footprint, salt)) : 0.0;
    float growth = vertical ? max(algae(p, footprint, salt),
                                  leak_algae(p, offset, footprint, salt)) : 0.0;
    float edge;
    float repair = patch_repair(p, footprint, salt, edge);
    vec3 f = vec3(1.0 + mottle + hue, 1.0 + mottle, 1.0 + mottle - hue)
             * (1.0 - rain) * (1.0 - dirt) * (1.0 - wet)
             * mix(vec3(1.0), vec3(0.80, 0.62, 0.45), 0.6 * rust)
             * mix(vec3(1.0), algae_tint(salt), growth);
    f = mix(f * detail, vec3(2.1, 2.1, 2.05), 0.75 * bloom);
    // Newer mortar: lighter and greyer, its paste finer (a third of the detail's contrast).
    vec3 mortar = vec3(1.14, 1.15, 1.17) * (1.0 + 0.33 * (detail - 1.0)) * (1.0 + 0.3 * mottle);
    return max(mix(f, mortar, repair) * (1.0 - 0.45 * edge), 0.0);
}
