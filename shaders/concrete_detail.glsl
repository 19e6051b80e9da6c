// Formed concrete's millimetre-to-decimetre detail, evaluated per fragment at the mesh-frame
// position (docs/design.md, "Concrete detail"): mottled cement paste, sand grains, pores, bug
// holes, plywood grain and the formwork's joints and tie holes. A repository image gives a
// member its colour and stains but, magnified to 1-2 mm per pixel, no contrast at the pixel
// scale, and it repeats; this detail is hashed from integer cells, so it never repeats, and
// each feature fades to its mean once a pixel's footprint nears its size (no aliasing).
// The result multiplies the base colour. Deterministic: a function of the position, the
// normal's dominant axis and the part's seed alone.

// Chris Wellons' lowbias32: a 32-bit integer hash with good avalanche.
uint detail_hash(uint x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

uint cell_hash(ivec2 c, uint salt) {
    return detail_hash(uint(c.x) * 0x9e3779b9u ^ detail_hash(uint(c.y) ^ salt));
}

float unit_float(uint h) {  // [0, 1)
    return float(h >> 8) * (1.0 / 16777216.0);
}

// How much of a feature of this size shows: all of it where it spans two pixels or more,
// none (its mean) where it spans one or less.
float resolved(float size_m, float footprint_m) {
    return clamp(size_m / footprint_m - 1.0, 0.0, 1.0);
}

// The share of a pixel of footprint fp that a disk of radius r covers, at distance d from
// its centre: antialiased over one pixel, and for a disk smaller than the pixel, no more than
// its area's share (so that small features fade to their mean, not to speckle).
float disk(float d, float r, float fp) {
    return clamp((r - d) / fp + 0.5, 0.0, 1.0) * min(1.0, 4.0 * r * r / (fp * fp));
}

// Smooth value noise in [-1, 1] with unit lattice spacing.
float value_noise(vec2 q, uint salt) {
    vec2 cell = floor(q), f = q - cell, u = f * f * (3.0 - 2.0 * f);
    ivec2 c = ivec2(cell);
    float a = unit_float(cell_hash(c, salt)), b = unit_float(cell_hash(c + ivec2(1, 0), salt));
    float d = unit_float(cell_hash(c + ivec2(0, 1), salt));
    float e = unit_float(cell_hash(c + ivec2(1, 1), salt));
    return 2.0 * mix(mix(a, b, u.x), mix(d, e, u.x), u.y) - 1.0;
}

// Cement paste: value noise in octaves from 64 mm down to 1 mm, each +-9 %.
float paste(vec2 p, float footprint, uint salt) {
    float sum = 0.0, size = 0.064;
    for (int k = 0; k < 7; ++k) {
        sum += 0.09 * resolved(size, footprint) * value_noise(p / size, salt + uint(k));
        size *= 0.5;
    }
    return sum;
}

// Sand and aggregate: in a share of the cells of size_m, one grain set in the paste, of mean
// radius 0.2-0.38 of the cell, stretched up to 1.6:1 at a random angle, its outline frayed
// inwards by up to 23 % by noise at a sixth of the cell, and placed whole inside its cell; of a
// shade in [-1, 1] (light quartz to dark minerals) that fades towards its rim, where the paste
// skin covers it; 0 in the paste between grains. Grains, not a tessellation: cells that each
// fill with one shade read as tiles (polygon edges a photograph never shows), and one cell per
// level costs well under a 3x3 Voronoi search.
float grains(vec2 p, float footprint, float size_m, float share, uint salt) {
    vec2 q = p / size_m, cell = floor(q);
    uint h = cell_hash(ivec2(cell), salt);
    float r = 0.2 + 0.18 * unit_float(detail_hash(h));
    float stretch = sqrt(1.0 + 0.6 * unit_float(detail_hash(h ^ 3u)));
    float reach = r * stretch;  // the long half-axis: at most 0.48 of the cell
    vec2 centre = cell + reach + (1.0 - 2.0 * reach) * vec2(unit_float(detail_hash(h ^ 1u)),
                                                            unit_float(detail_hash(h ^ 2u)));
    float angle = 6.2831853 * unit_float(detail_hash(h ^ 4u));
    vec2 d = q - centre, along = vec2(cos(angle), sin(angle));
    float dist = length(vec2(dot(d, along) / stretch, (d.x * along.y - d.y * along.x) * stretch))
                 * (1.15 + 0.15 * value_noise(q * 6.0, salt ^ 0x68e31da4u));  // frays inwards
    float shade = 2.0 * unit_float(detail_hash(h ^ 5u)) - 1.0;
    float rim = sqrt(clamp(1.0 - dist / r, 0.0, 1.0));
    return float(unit_float(h) < share) * shade * disk(dist, r, footprint / size_m)
           * mix(1.0, rim, resolved(0.5 * r * size_m, footprint));
}

// Holes (pores, bug holes): in a share of the cells of size_m, a disk of radius log-uniform
// in [r0, r1] inside its cell; the share of the pixel the disk covers.
float holes(vec2 p, float footprint, float size_m, float share, float r0, float r1,
            uint salt) {
    vec2 q = p / size_m;
    uint h = cell_hash(ivec2(floor(q)), salt);
    float r = r0 * pow(r1 / r0, unit_float(detail_hash(h))) / size_m;
    vec2 centre = floor(q) + r + (1.0 - 2.0 * r) * vec2(unit_float(detail_hash(h ^ 1u)),
                                                        unit_float(detail_hash(h ^ 2u)));
    return disk(length(q - centre), r, footprint / size_m) * float(unit_float(h) < share);
}

// Formwork: plywood panels 1.22 x 2.44 m (a dark joint line 4 mm wide between them), tie
// holes every 0.6 m (25 mm, mortar-filled: lighter), and the plywood's grain along the panel.
// A plywood sheet's size, metres (weathering.glsl's marks below the joints read it too).
const vec2 FORMWORK_PANEL_M = vec2(1.22, 2.44);
// The formwork's panel and tie grid offset (in grid units) on the face of salt.
vec2 formwork_offset(uint salt) {
    return vec2(unit_float(detail_hash(salt ^ 7u)), unit_float(detail_hash(salt ^ 9u)));
}

float formwork(vec2 p, float footprint, uint salt) {
    vec2 offset = formwork_offset(salt);
    vec2 panel = fract(p / FORMWORK_PANEL_M + offset) * FORMWORK_PANEL_M;
    vec2 edge = min(panel, FORMWORK_PANEL_M - panel);
    float joint = clamp((0.002 + 0.5 * footprint - min(edge.x, edge.y)) / footprint, 0.0, 1.0);
    vec2 tie = fract(p / 0.6 + offset) * 0.6 - 0.3;
    float plug = disk(length(tie), 0.0125, footprint);
    float grain = 0.03 * resolved(0.002, footprint)
                  * value_noise(vec2(p.x / 0.002, p.y / 0.04), salt ^ 11u);
    return grain - 0.25 * joint * resolved(0.004, footprint) + 0.12 * plug;
}

// The detail's factor on the base colour at mesh-frame position pos (relative to the part's
// own origin: float32 keeps sub-millimetre steps there), normal n (mesh frame), for part seed.
// The face's own plane, by the normal's dominant axis (returned: 0, 1 or 2): p, the position
// in it (its second coordinate z where the axis is x or y), and its salt; each axis and side
// its own salt, so that a member's faces differ.
int detail_face(vec3 pos, vec3 n, uint seed, out vec2 p, out uint salt) {
    vec3 a = abs(n);
    int axis = a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
    p = axis == 0 ? pos.yz : (axis == 1 ? pos.xz : pos.xy);
    float side = axis == 0 ? n.x : (axis == 1 ? n.y : n.z);
    salt = detail_hash(seed ^ uint(2 * axis + int(side > 0.0)) * 0x27d4eb2du);
    return axis;
}

float concrete_detail(vec3 pos, vec3 n, uint seed) {
    vec2 p;
    uint salt;
    detail_face(pos, n, seed, p, salt);
    float footprint = max(max(length(dFdx(pos)), length(dFdy(pos))), 1e-6);
    float shade = 1.0 + paste(p, footprint, salt)
                  + 0.45 * grains(p, footprint, 0.0012, 0.9, salt ^ 13u)
                  + 0.55 * grains(p, footprint, 0.0025, 0.8, salt ^ 3u)
                  + 0.45 * grains(p, footprint, 0.005, 0.5, salt ^ 12u)
                  + 0.30 * grains(p, footprint, 0.012, 0.2, salt ^ 4u)
                  + 0.40 * grains(p, footprint, 0.025, 0.5, salt ^ 14u)
                  + formwork(p, footprint, salt);
    float dark = 0.55 * holes(p, footprint, 0.006, 0.40, 0.0002, 0.0008, salt ^ 5u)
                 + 0.65 * holes(p, footprint, 0.025, 0.12, 0.0005, 0.004, salt ^ 6u);
    return max(shade * (1.0 - dark), 0.0);
}
