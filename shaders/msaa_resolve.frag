#version 330 core
// The multisampled colour, resolved: each sample takes the colour that the single-sample
// colour pass shaded at a pixel centre on the sample's surface (same normal, nearest depth):
// its own pixel's, or across a silhouette one of its four neighbours'. A sample that no
// surface covers takes the sky of the nearest pixel centre that shows sky. The pixel is the
// mean of its samples. No branch depends on the lane: llvmpipe would run the work of one lane
// for its whole 4x4 block.
#include "msaa_inputs.glsl"

out vec4 f_color;

const ivec2 OFFSETS[5] = ivec2[5](ivec2(0), ivec2(1, 0), ivec2(-1, 0), ivec2(0, 1),
                                  ivec2(0, -1));

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy), last = textureSize(u_labels, 0) - 1;
    vec4 labels[5], shaded[5];
    vec3 normals[5];
    for (int i = 0; i < 5; ++i) {
        ivec2 q = clamp(px + OFFSETS[i], ivec2(0), last);
        labels[i] = texelFetch(u_labels, q, 0);  // a = 0 where no part was drawn
        normals[i] = texelFetch(u_normals, q, 0).xyz;
        shaded[i] = texelFetch(u_shaded, q, 0);
    }
    vec4 sum = vec4(0.0);
    for (int s = 0; s < MSAA_SAMPLES; ++s) {
        vec4 surface = texelFetch(u_sample_surface, px, s);
        float depth = max(texelFetch(u_sample_depth, px, s).r, 1e-30);
        vec4 best = shaded[0];
        float best_cost = 1e30;
        for (int i = 0; i < 5; ++i) {
            // On a surface: 1 - cos between the normals plus the relative depth gap; in the
            // sky: whether the candidate shows a surface. A nudge keeps the own pixel's ties.
            float on_surface = 1.0 - labels[i].a * dot(normals[i], surface.xyz)
                               + abs(labels[i].b - depth) / depth;
            float cost = mix(labels[i].a, on_surface, surface.a) + (i == 0 ? 0.0 : 1e-5);
            best = cost < best_cost ? shaded[i] : best;
            best_cost = min(cost, best_cost);
        }
        sum += best;
    }
    f_color = sum / float(MSAA_SAMPLES);
}
