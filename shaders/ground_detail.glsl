// The ground's centimetre detail at 0.3-3 m (docs/design.md, "The ground up close"). The
// repository image gives the ground its colour over metres, but at a texel per several
// centimetres it is a flat wash where a camera at a column's foot sees it. This detail is hashed
// from integer cells as concrete's is (concrete_detail.glsl: its hash, noise, grains and disks),
// per fragment in the ground's plane (mesh frame: the ground's z is up), each feature fading to
// its mean once a pixel's footprint nears its size:
// - the cover (the image's grass or gravel) worn through to bare soil in patches where noise
//   over 1 m down to 7.5 cm passes a threshold: 61 % of the ground;
// - the soil's colour, a brown of 6.7-10.9 % albedo (luminance), mottled by noise in six
//   octaves from 0.3 m down to 9 mm; damp in patches of 0.7 m (34 % of it: water in its pores
//   takes the place of air, as in concrete: half as bright);
// - crumbs and clods in cells of 5, 12 and 30 mm, lighter or darker than the soil, and voids
//   of 1-4 mm between them, dark;
// - stones of 1-5 cm, lighter or darker than the soil or cover they lie in;
// - leaf litter: in some cells of 12 cm a leaf 2-6 cm long, brown to ochre, flat on the top.
// Deterministic: a function of the position and the part's seed alone.
#include "weathering.glsl"

const vec3 SOIL_BROWN = vec3(0.105, 0.080, 0.058);   // linear albedo of dry topsoil
const vec3 LEAF_BROWN = vec3(0.16, 0.085, 0.035);
const vec3 LEAF_OCHRE = vec3(0.36, 0.24, 0.07);

// A leaf in a share of the cells of size_m: an ellipse of length 2-6 cm, a third as wide, at
// a random angle; the share of the pixel it covers, and its hue (0 brown, 1 ochre).
float leaf(vec2 p, float footprint, float size_m, float share, uint salt, out float hue) {
    vec2 q = p / size_m, cell = floor(q);
    uint h = cell_hash(ivec2(cell), salt);
    float half_len = (0.01 + 0.02 * unit_float(detail_hash(h ^ 1u))) / size_m;
    vec2 centre = cell + 0.5 + (0.5 - half_len) * (2.0 * vec2(unit_float(detail_hash(h ^ 2u)),
                                                             unit_float(detail_hash(h ^ 3u))) - 1.0);
    float angle = 6.2831853 * unit_float(detail_hash(h ^ 4u));
    vec2 d = q - centre, along = vec2(cos(angle), sin(angle));
    float r = length(vec2(dot(d, along), 3.0 * (d.x * along.y - d.y * along.x)));
    hue = unit_float(detail_hash(h ^ 5u));
    return float(unit_float(h) < share) * disk(r, half_len, footprint / size_m);
}

// Each patchy feature below, once a pixel's footprint outgrows it, blends to its share of the
// ground's area (measured in the shader harness, tests/test_ground_detail.py): a pixel far
// away reads the patches' mean rather than whichever patch its centre falls in (that aliased,
// speckling distant ground soil and cover).
const float BARE_MEAN = 0.61;    // the bare soil's share of the ground (measured)
const float DAMP_MEAN = 0.343;   // the damp patches' share of the soil (measured)
// The voids' share: 0.3 of the 15 mm cells hold a disk of radius log-uniform in 1-4 mm,
// whose mean r^2 is (4^2 - 1^2) mm^2 / (2 ln 4).
const float VOID_MEAN = 0.3 * 3.14159265 * 5.4101e-6 / (0.015 * 0.015);
// The leaves' share: 0.3 of the 12 cm cells hold an ellipse of half-length L uniform in 1-3 cm
// and a third as wide, of mean area pi E[L^2] / 3, E[L^2] = (3^3 - 1^3) cm^3 / (3 x 2 cm).
const float LEAF_MEAN = 0.3 * 3.14159265 * 4.3333e-4 / 3.0 / (0.12 * 0.12);

// The bare soil's share of the pixel at p: where noise over 1 m down to 7.5 cm passes a
// threshold, the cover has worn through (a soft edge of a few centimetres).
float bare_soil(vec2 p, float footprint, uint salt) {
    float worn = value_noise(p / 1.0, salt ^ 1u) + 0.5 * octaves(p, 0.3, 3, 0.5, footprint, salt ^ 2u);
    return mix(BARE_MEAN, smoothstep(-0.25, -0.05, worn), resolved(0.5, footprint));
}

// The damp patches' share of the pixel at p: where noise at 0.7 m passes a threshold.
float damp_soil(vec2 p, float footprint, uint salt) {
    return mix(DAMP_MEAN, smoothstep(0.1, 0.3, value_noise(p / 0.7, salt ^ 4u)),
               resolved(0.35, footprint));
}

// The ground's colour at point p of its plane, seen by a pixel of this footprint (metres),
// from the base colour ``cover`` (linear) of its image there, for part seed.
vec3 ground_at(vec3 cover, vec2 p, float footprint, uint seed) {
    uint salt = detail_hash(seed ^ 0x5bd1e995u);
    float bare = bare_soil(p, footprint, salt);
    float albedo = 0.8 + 0.5 * unit_float(detail_hash(salt ^ 3u));  // 0.8-1.3 x SOIL_BROWN
    float damp = damp_soil(p, footprint, salt);
    vec3 soil = SOIL_BROWN * albedo * (1.0 + 0.35 * octaves(p, 0.3, 6, 0.6, footprint, salt ^ 5u))
                * (1.0 - 0.5 * damp);
    // Crumbs and clods, and the dark voids between them.
    float crumbs = 0.8 * grains(p, footprint, 0.005, 0.6, salt ^ 6u)
                   + 0.6 * grains(p, footprint, 0.012, 0.4, salt ^ 7u)
                   + 0.5 * grains(p, footprint, 0.03, 0.3, salt ^ 8u);
    float voids = 0.5 * mix(VOID_MEAN, holes(p, footprint, 0.015, 0.3, 0.001, 0.004, salt ^ 9u),
                            resolved(0.015, footprint));
    soil *= max((1.0 + crumbs) * (1.0 - voids), 0.0);
    vec3 ground = mix(cover * (1.0 + 0.3 * octaves(p, 0.1, 4, 0.6, footprint, salt ^ 10u)),
                      soil, bare);
    // Stones, on the soil and in the cover: lighter or darker than what they lie in, frayed.
    float stones = 0.7 * grains(p, footprint, 0.06, 0.2, salt ^ 11u)
                   + 0.5 * grains(p, footprint, 0.025, 0.15, salt ^ 13u);
    ground *= max(1.0 + stones, 0.0);
    // Leaves on top.
    float hue;
    float shown = resolved(0.12, footprint);
    float cover_leaf = mix(LEAF_MEAN, leaf(p, footprint, 0.12, 0.3, salt ^ 12u, hue), shown);
    return mix(ground, mix(LEAF_BROWN, LEAF_OCHRE, mix(0.5, hue, shown)), cover_leaf);
}

// ground_at at position pos (relative to the part's box's lower corner), its footprint from
// the position's screen-space derivatives.
vec3 ground_detail(vec3 cover, vec3 pos, uint seed) {
    return ground_at(cover, pos.xy, max(max(length(dFdx(pos)), length(dFdy(pos))), 1e-6), seed);
}
