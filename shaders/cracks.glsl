// Cracks as straight segments with a width, evaluated per fragment in the mesh's own frame,
// relative to the grid's lower corner (the vertex stage subtracts it, mesh.vert, so that the
// positions keep their precision far from the mesh frame's origin; glsynth.render.cracks_index
// packs the segments so; docs/design.md, "Cracks", gives the rules). The
// fragment reads its grid cell's list of segments; from each: the distance to its centreline,
// the width there, and the pixel footprint across it on the surface.
uniform sampler2D u_crack_segments;  // RGBA32F, 2 texels per segment: end point (m, relative
                                     // to the grid's lower corner), width (mm)
uniform isampler2D u_crack_cells;    // (first entry, count) per grid cell
uniform isampler2D u_crack_entries;  // segment ids, cell after cell
uniform float u_crack_cell_m;        // its cells' edge
uniform ivec3 u_crack_dims;          // its cells along x, y, z
uniform bool u_crack_rough;          // carry each segment's path on below its ends (below)
uniform float u_crack_footprint_m;   // the half footprint its own cell's list serves

// A crack's path is self-affine: the lateral offset between points x apart has variance
// (A xi)^2 (x / xi)^(2H), H fine below the coarse aggregate's size xi, coarse above it. The
// CRACK_* constants (xi, A, the H's, the reach, levels and lips) are macros, defined in
// glsynth.appearance.crack_paths, which generates the same paths down to a few centimetres.

// Texel of entry i of a texture filled row by row, 2^CRACK_ROW_BITS texels a row
// (cracks_index.ROW): a mask and a shift, as llvmpipe divides integers one lane at a time
// (division here was a third of a label pass with cracks).
ivec2 crack_texel(int i) {
    return ivec2(i & ((1 << CRACK_ROW_BITS) - 1), i >> CRACK_ROW_BITS);
}

// Parameter t in [0, 1] of the point of segment a-b nearest to p.
float segment_param(vec3 p, vec3 a, vec3 b) {
    vec3 ab = b - a;
    float length2 = dot(ab, ab);
    return length2 > 0.0 ? clamp(dot(p - a, ab) / length2, 0.0, 1.0) : 0.0;
}

// The width at parameter t, linear between the end points' widths (exact where they agree).
float crack_width_at(float w0, float w1, float t) {
    return w0 + (w1 - w0) * t;
}

// The share of a box filter of width f centred d from a band's centreline that the band of
// width w covers: the overlap of [d - f/2, d + f/2] with [-w/2, w/2], over f.
float band_coverage(float d, float w, float f) {
    float overlap = min(d + 0.5 * f, 0.5 * w) - max(d - 0.5 * f, -0.5 * w);
    return clamp(overlap / f, 0.0, 1.0);
}

// The pixel's extent across a crack running along ``along``, on the surface whose
// screen-space derivatives of position are dpdx, dpdy: the pixel square's image on the
// surface, projected on the surface direction perpendicular to the crack. A crack direction
// along the normal (a segment on the next face of a corner) has no such direction: the
// footprint's larger extent then.
float footprint_across(vec3 dpdx, vec3 dpdy, vec3 along) {
    vec3 across = cross(cross(dpdx, dpdy), along);
    float size = length(across);
    if (!(size > 1e-3 * length(dpdx) * length(dpdy) * length(along)))
        return max(length(dpdx) + length(dpdy), 1e-12);
    across /= size;
    return max(abs(dot(dpdx, across)) + abs(dot(dpdy, across)), 1e-12);
}

// The grid cell holding p (relative to the grid's lower corner), along x, y and z.
ivec3 crack_grid(vec3 p) {
    return ivec3(floor(p / u_crack_cell_m));
}

// The index of grid cell c (inside the grid) in the cell texture: x fastest.
int crack_cell_index(ivec3 c) {
    return c.x + u_crack_dims.x * (c.y + u_crack_dims.y * c.z);
}

// lowbias32 (Wellons): a 32-bit integer hash, the same bits in numpy.
uint crack_hash(uint x) {
    x ^= x >> 16u; x *= 0x7feb352du; x ^= x >> 15u; x *= 0x846ca68bu; x ^= x >> 16u;
    return x;
}

// A draw of mean 0 and variance 1 (the sum of two uniforms) keyed by a segment's seed, a level
// of halving and an interval's index in it.
float crack_draw(uint seed, int level, uint index) {
    uint h1 = crack_hash(seed + uint(level) * 0x9e3779b9u + index * 0x85ebca6bu);
    uint h2 = crack_hash(h1);
    return (float(h1 >> 8u) + float(h2 >> 8u) + 1.0) / 16777216.0 * 2.449489743 - 2.449489743;
}

// S(x), the variance of the lateral offset between points x apart (m^2).
float crack_structure(float x) {
    float h = x < CRACK_AGGREGATE_M ? CRACK_HURST_FINE : CRACK_HURST_COARSE;
    return pow(CRACK_ROUGHNESS * CRACK_AGGREGATE_M, 2.0) * pow(x / CRACK_AGGREGATE_M, 2.0 * h);
}

// The lateral offset (m) at parameter t of a segment ``length_m`` long, by random midpoint
// displacement from 0 at both ends (the polyline's vertices), halving while the new points
// lie at least ``finest_m`` apart; clamped to CRACK_REACH_M. Then the piece of the path that
// holds t: its slope across the chord (0 where the clamp holds it), and how far (m, along the
// chord) it runs before and after t.
vec4 crack_offset(float t, float length_m, uint seed, float finest_m) {
    float lo = 0.0, hi = 0.0, a = 0.0, b = 1.0, interval = length_m;
    uint index = 0u;
    float s_whole = crack_structure(interval);
    // Counted before the loop, not bounded by a constant in it: a loop with a constant bound
    // is unrolled, and llvmpipe runs unrolled code for every pixel, needed or not (40 % of a
    // view's time).
    float finest = max(finest_m, length_m * exp2(-float(CRACK_LEVELS)));
    int levels = int(floor(log2(length_m / finest)));
    for (int level = 0; level < levels; ++level) {
        float s_half = crack_structure(0.5 * interval);
        float sd = sqrt(max(s_half - 0.25 * s_whole, 0.0));
        s_whole = s_half;
        float mid = 0.5 * (lo + hi) + sd * crack_draw(seed, level, index);
        float m = 0.5 * (a + b);
        bool left = t < m;
        lo = left ? lo : mid;
        hi = left ? mid : hi;
        a = left ? a : m;
        b = left ? m : b;
        index = 2u * index + (left ? 0u : 1u);
        interval *= 0.5;
    }
    float offset = mix(lo, hi, (t - a) / (b - a));
    float slope = abs(offset) > CRACK_REACH_M ? 0.0 : (hi - lo) / interval;
    return vec4(clamp(offset, -CRACK_REACH_M, CRACK_REACH_M), slope, (t - a) * length_m,
                (b - t) * length_m);
}

// The surface's normal with its largest component positive, whichever way the view sees it:
// the side a path strays to belongs to the surface, not to the view.
vec3 crack_normal(vec3 dpdx, vec3 dpdy) {
    vec3 n = cross(dpdx, dpdy), m = abs(n);
    float lead = m.x >= m.y && m.x >= m.z ? n.x : (m.y >= m.z ? n.y : n.z);
    return lead < 0.0 ? -n : n;
}

// The darkening a crack gives a pixel, as a share of the interior's (u_crack_contrast): the
// band it covers; on a rough crack a chip ``chip`` m deep out of the lip on the pixel's side
// (crack_chip), darkened by CRACK_CHIP_SHARE of the interior's; beyond it the lips, rounded
// edges min(w, CRACK_LIP_M) wide each side, which turn from the light and darken by
// CRACK_LIP_SHARE of the interior's. The lips are surface, not crack: they label nothing.
float crack_coverage(float d, float w, float chip, float f) {
    float inside = band_coverage(d, w, f);
    if (!u_crack_rough) return inside;
    float broken = band_coverage(d, w + 2.0 * chip, f);
    float lips = band_coverage(d, w + 2.0 * (chip + min(w, CRACK_LIP_M)), f) - broken;
    return inside + CRACK_CHIP_SHARE * (broken - inside) + CRACK_LIP_SHARE * lips;
}

// How deep (m) a chip breaks out of one lip (``side`` 0 or 1) of a crack w m wide, u m along
// its segment (``seed``'s), at one scale: each cell along the crack, ``scale`` times
// CRACK_CHIP_CELL_WIDTHS widths + CRACK_CHIP_CELL_M long, holds one with chance ``chance``, a
// half-ellipse inside the cell, a quarter to a half of it long, ``scale`` times CRACK_CHIP_MIN
// to CRACK_CHIP_MAX widths deep.
float crack_chip_at(float u, uint side, uint seed, float w, float scale, float chance) {
    float x = u / (scale * (CRACK_CHIP_CELL_WIDTHS * w + CRACK_CHIP_CELL_M));
    uint h = crack_hash(seed ^ (side * 0x27d4eb2du) ^ crack_hash(uint(max(x, 0.0))
                                                                 + floatBitsToUint(scale)));
    if (float(h & 0xffffu) >= chance * 65536.0) return 0.0;
    float centre = 0.25 + 0.5 * float((h >> 16u) & 0xffu) / 255.0;
    float half_length = 0.125 + 0.125 * float(h >> 24u) / 255.0;
    float q = (fract(x) - centre) / half_length;
    float depth = mix(CRACK_CHIP_MIN, CRACK_CHIP_MAX, float(crack_hash(h) >> 8u) / 16777216.0);
    return q * q < 1.0 ? scale * depth * w * sqrt(1.0 - q * q) : 0.0;
}

// How deep (m) the lip on one side is broken: chips (crack_chip_at) at two scales, the finer
// a quarter of the coarser and twice as common, so that an edge is ragged at the width and at
// the pixel. Real lips break where the crack's faces grind as it opens and closes; the chips
// scale with the crack, so a hairline one has none a pixel could show. A chip is surface,
// not the opening: it darkens and labels nothing (crack_apply), as the lips.
float crack_chip(float u, uint side, uint seed, float w) {
    return max(crack_chip_at(u, side, seed, w, 1.0, CRACK_CHIP_CHANCE),
               crack_chip_at(u, side, seed, w, 0.25, 2.0 * CRACK_CHIP_CHANCE));
}

struct CrackHit {
    float coverage;  // the largest share of the pixel a crack covers
    float width_mm;  // the width of the nearest crack that labels the pixel; 0 if none
    bool labelled;   // a crack covers the pixel's centre or its centreline crosses the pixel
};

// One crack's share in ``hit``: at distance d from its centreline, width w (m, width_mm in
// mm) there, a chip ``chip`` m deep out of the lip on the pixel's side (surface, like the
// lips: it darkens and labels nothing), the pixel's footprint f across it.
void crack_apply(float d, float w, float chip, float width_mm, float f, inout CrackHit hit,
                 inout float nearest) {
    hit.coverage = max(hit.coverage, crack_coverage(d, w, chip, f));
    bool labels = d <= 0.5 * max(w, f) && w > 0.0;  // closed at a tip: no crack to label
    hit.width_mm = labels && d < nearest ? width_mm : hit.width_mm;
    nearest = labels ? min(d, nearest) : nearest;
    hit.labelled = hit.labelled || labels;
}

// Segments whose rough paths may reach the pixel wait in ``near``, the two nearest to p by
// their chords (ids; -1: none; a segment seen again is kept once), and are drawn after the
// walk (crack_rough): the path's refinement runs at most twice per pixel rather than for every
// listed segment, which keeps a rough network's cost that of a straight one. A pixel within a
// path's reach of three segments or more (where forks meet) loses the third's.
void crack_defer(int s, float d, inout ivec2 near, inout vec2 near_d) {
    if (s == near.x || s == near.y) return;
    if (d < near_d.x) {
        near = ivec2(s, near.x);
        near_d = vec2(d, near_d.x);
    } else if (d < near_d.y) {
        near.y = s;
        near_d.y = d;
    }
}

// The segments listed in grid cell ``cell`` (crack_cell_index) into ``hit``, or into ``near``
// where a rough path may reach p; ``nearest``: the distance to the nearest labelling crack so
// far. A segment seen again changes nothing.
void crack_walk(int cell, vec3 p, vec3 dpdx, vec3 dpdy, inout CrackHit hit,
                inout float nearest, inout ivec2 near, inout vec2 near_d) {
    float size = length(dpdx) + length(dpdy);
    ivec2 list = texelFetch(u_crack_cells, crack_texel(cell), 0).xy;
    for (int k = 0; k < list.y; ++k) {
        int s = texelFetch(u_crack_entries, crack_texel(list.x + k), 0).r;
        vec4 a = texelFetch(u_crack_segments, crack_texel(2 * s), 0);
        vec4 b = texelFetch(u_crack_segments, crack_texel(2 * s + 1), 0);
        float t = segment_param(p, a.xyz, b.xyz);
        float d = distance(p, a.xyz + (b.xyz - a.xyz) * t);
        float width_mm = crack_width_at(a.w, b.w, t);
        float w = 0.001 * width_mm;
        if (u_crack_rough && t > 0.0 && t < 1.0
            && d < CRACK_REACH_M + 0.5 * size + (0.5 + CRACK_CHIP_MAX) * w + CRACK_LIP_M)
            crack_defer(s, d, near, near_d);
        else
            crack_apply(d, w, 0.0, width_mm,
                        footprint_across(dpdx, dpdy, b.xyz - a.xyz), hit, nearest);
    }
}

// The squared distance (m^2, on the surface) from a pixel ``across`` m off the path, measured
// across the chord at the pixel's place along it, to the path's piece there: slope ``slope``,
// running ``before`` m back and ``after`` m on along the chord (crack_offset). A crack is its
// path swept by a disc of its width; measured to the piece beside it alone, a pixel is drawn
// inside that sweep (beside a steep neighbouring piece a few per cent of the sweep is left
// out: steps of one piece's rise on the lips). Measured to the piece's infinite tangent line
// instead, where a piece shorter than the width is steep (a tenth of the pieces a tenth of a
// millimetre long climb more than their length), the band reached (w / 2)(sqrt(1 + slope^2)
// - 1) past the crack, a needle that no crack has.
float crack_piece_distance2(float across, float slope, float before, float after) {
    vec2 dir = vec2(1.0, slope);
    float k = clamp(across * slope / dot(dir, dir), -before, after);
    vec2 gap = vec2(0.0, across) - k * dir;
    return dot(gap, gap);
}

// Segment s drawn along its rough path (crack_offset), across the chord on the surface.
void crack_rough(int s, vec3 p, vec3 dpdx, vec3 dpdy, inout CrackHit hit, inout float nearest) {
    vec4 a = texelFetch(u_crack_segments, crack_texel(2 * s), 0);
    vec4 b = texelFetch(u_crack_segments, crack_texel(2 * s + 1), 0);
    float t = segment_param(p, a.xyz, b.xyz);
    vec3 ab = b.xyz - a.xyz, r = p - (a.xyz + ab * t), along = ab;
    float d = length(r), width_mm = crack_width_at(a.w, b.w, t), chip = 0.0;
    vec3 across = cross(crack_normal(dpdx, dpdy), ab);
    if (dot(across, across) > 0.0) {
        across = normalize(across);
        uint seed = crack_hash(floatBitsToUint(a.w) ^ crack_hash(floatBitsToUint(b.w)));
        vec4 o = crack_offset(t, length(ab), seed, 0.5 * (length(dpdx) + length(dpdy)));
        float ra = dot(r, across);
        d = sqrt(crack_piece_distance2(ra - o.x, o.y, o.z, o.w)
                 + max(dot(r, r) - ra * ra, 0.0));
        along = normalize(ab) + o.y * across;
        chip = crack_chip(t * length(ab), uint(ra >= o.x), seed, 0.001 * width_mm);
    }
    crack_apply(d, 0.001 * width_mm, chip, width_mm, footprint_across(dpdx, dpdy, along), hit,
                nearest);
}

// The grid cells, lo to hi inclusive, whose lists a pixel at p with derivatives dpdx, dpdy
// reads. The own cell's list holds every crack that a pixel of half footprint up to
// u_crack_footprint_m needs; a pixel whose half footprint reaches further also reads every
// cell within the rest of it (each axis apart), up to one cell edge more each way
// (glsynth.render.cracks_index).
struct CrackBox {
    ivec3 lo;
    ivec3 hi;
};

CrackBox crack_box(vec3 p, vec3 dpdx, vec3 dpdy) {
    float h = u_crack_cell_m;
    float extra = clamp(0.5 * (length(dpdx) + length(dpdy)) - u_crack_footprint_m, 0.0, h);
    return CrackBox(max(crack_grid(p - extra), ivec3(0)),
                    min(crack_grid(p + extra), u_crack_dims - 1));
}

// The cracks at point p (mesh frame, relative to the grid's lower corner), seen through a
// pixel whose derivatives are dpdx, dpdy: the segments listed in its box's cells.
CrackHit crack_hit(vec3 p, vec3 dpdx, vec3 dpdy) {
    CrackHit hit = CrackHit(0.0, 0.0, false);
    float nearest = 1e30;
    CrackBox box = crack_box(p, dpdx, dpdy);
    ivec3 lo = box.lo, hi = box.hi;
    ivec2 near = ivec2(-1);
    vec2 near_d = vec2(1e30);
    // One loop over the box's cells in the order nested loops would take (x fastest, then y,
    // then z), the cell stepped along rather than divided out of the count: llvmpipe pays for
    // each level of nesting around crack_walk's own loop (docs/results.md, "An inspection
    // sample").
    ivec3 span = max(hi - lo + 1, ivec3(0));
    int cells = span.x * span.y * span.z;
    ivec3 c = lo;
    for (int i = 0; i < cells; ++i) {
        crack_walk(crack_cell_index(c), p, dpdx, dpdy, hit, nearest, near, near_d);
        bool wrap_x = c.x == hi.x, wrap_y = wrap_x && c.y == hi.y;
        c.x = wrap_x ? lo.x : c.x + 1;
        c.y = wrap_y ? lo.y : (wrap_x ? c.y + 1 : c.y);
        c.z = wrap_y ? c.z + 1 : c.z;
    }
    int deferred = int(near.x >= 0) + int(near.y >= 0);  // not unrolled (crack_offset)
    for (int i = 0; i < deferred; ++i)
        crack_rough(near[i], p, dpdx, dpdy, hit, nearest);
    return hit;
}
