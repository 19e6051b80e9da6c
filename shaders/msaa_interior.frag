#version 330 core
// The first step of the multisample resolve. A pixel whose samples all lie on the surface
// at its centre (the same normal within 2.6 degrees, depths spread by at most 0.2 % of the
// centre's, the centre's among them) takes the colour shaded at its centre, as a GPU's MSAA
// does inside a surface, and gets depth 0; the others get depth 1, and only there does the
// full resolve (msaa_resolve.frag, drawn at depth 1 with "<=") run: llvmpipe skips a 4x4
// block that fails the early depth test, so the candidates are weighed along edges only.
#include "msaa_inputs.glsl"

out vec4 f_color;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 labels = texelFetch(u_labels, px, 0);
    vec3 normal = texelFetch(u_normals, px, 0).xyz;
    bool interior = labels.a > 0.5;
    float lo = 1e30, hi = 0.0;
    for (int s = 0; s < MSAA_SAMPLES; ++s) {
        vec4 surface = texelFetch(u_sample_surface, px, s);
        float depth = texelFetch(u_sample_depth, px, s).r;
        interior = interior && surface.a > 0.5 && dot(surface.xyz, normal) > 0.999;
        lo = min(lo, depth);
        hi = max(hi, depth);
    }
    float centre = labels.b;
    interior = interior && hi - lo <= 0.002 * centre && centre >= lo - 1e-4 * centre
               && centre <= hi + 1e-4 * centre;
    f_color = texelFetch(u_shaded, px, 0);
    gl_FragDepth = interior ? 0.0 : 1.0;
}
