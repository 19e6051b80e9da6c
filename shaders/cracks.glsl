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

// Texel of entry i of a texture filled row by row.
ivec2 crack_texel(int i, int row) {
    return ivec2(i % row, i / row);
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

struct CrackHit {
    float coverage;  // the largest share of the pixel a crack covers
    float width_mm;  // the width of the nearest crack that labels the pixel; 0 if none
    bool labelled;   // a crack covers the pixel's centre or its centreline crosses the pixel
};

// The segments listed in grid cell ``cell`` (crack_cell_index) into ``hit``; ``nearest``:
// the distance to the nearest labelling crack so far. A segment seen again changes nothing.
void crack_walk(int cell, vec3 p, vec3 dpdx, vec3 dpdy, inout CrackHit hit,
                inout float nearest) {
    int cell_row = textureSize(u_crack_cells, 0).x, entry_row = textureSize(u_crack_entries, 0).x;
    int segment_row = textureSize(u_crack_segments, 0).x;
    ivec2 list = texelFetch(u_crack_cells, crack_texel(cell, cell_row), 0).xy;
    for (int k = 0; k < list.y; ++k) {
        int s = texelFetch(u_crack_entries, crack_texel(list.x + k, entry_row), 0).r;
        vec4 a = texelFetch(u_crack_segments, crack_texel(2 * s, segment_row), 0);
        vec4 b = texelFetch(u_crack_segments, crack_texel(2 * s + 1, segment_row), 0);
        float t = segment_param(p, a.xyz, b.xyz);
        float d = distance(p, a.xyz + (b.xyz - a.xyz) * t);
        float width_mm = crack_width_at(a.w, b.w, t);
        float w = 0.001 * width_mm, f = footprint_across(dpdx, dpdy, b.xyz - a.xyz);
        hit.coverage = max(hit.coverage, band_coverage(d, w, f));
        bool labels = d <= 0.5 * max(w, f);
        hit.width_mm = labels && d < nearest ? width_mm : hit.width_mm;
        nearest = labels ? min(d, nearest) : nearest;
        hit.labelled = hit.labelled || labels;
    }
}

// The cracks at point p (mesh frame, relative to the grid's lower corner), seen through a pixel whose derivatives are dpdx, dpdy.
// The own cell's list holds every crack within one cell edge beyond its edge; a pixel whose
// half footprint reaches further also reads the cells within the rest of it, up to one more
// each way (glsynth.render.cracks_index).
CrackHit crack_hit(vec3 p, vec3 dpdx, vec3 dpdy) {
    CrackHit hit = CrackHit(0.0, 0.0, false);
    float nearest = 1e30;
    float h = u_crack_cell_m;
    float extra = clamp(0.5 * (length(dpdx) + length(dpdy)) - h, 0.0, h);
    ivec3 lo = max(crack_grid(p - extra), ivec3(0));
    ivec3 hi = min(crack_grid(p + extra), u_crack_dims - 1);
    for (int z = lo.z; z <= hi.z; ++z)
        for (int y = lo.y; y <= hi.y; ++y)
            for (int x = lo.x; x <= hi.x; ++x)
                crack_walk(crack_cell_index(ivec3(x, y, z)), p, dpdx, dpdy, hit, nearest);
    return hit;
}
