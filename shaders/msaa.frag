#version 330 core
// The multisampled colour pass: each sample takes the colour that the single-sample colour
// pass shaded at a pixel centre on this sample's surface (same normal, nearest depth): its own
// pixel's, or across a silhouette one of its four neighbours'. llvmpipe runs a multisampled
// pass's shader for every 4x4 block a triangle touches, hidden or not (no early depth
// rejection under MSAA), so the costly shading runs once per visible pixel in the
// single-sample pass and this shader only looks up. No branch or loop depends on the lane:
// llvmpipe would run the work of one lane for its whole block.
in vec3 v_view_pos;
in vec3 v_normal;

uniform sampler2D u_labels;     // (component, damage, linear depth, hit) per pixel
uniform sampler2D u_normals;    // the single-sample pass's shading normal per pixel
uniform sampler2D u_shaded;     // its colour per pixel

out vec4 f_color;

#include "facing_normal.glsl"

const ivec2 OFFSETS[5] = ivec2[5](ivec2(0), ivec2(1, 0), ivec2(-1, 0), ivec2(0, 1),
                                  ivec2(0, -1));

void main() {
    vec3 n = facing_normal(v_normal, normalize(-v_view_pos));
    ivec2 px = ivec2(gl_FragCoord.xy), last = textureSize(u_labels, 0) - 1;
    float depth = -v_view_pos.z;
    ivec2 best = px;
    float best_cost = 1e30;
    for (int i = 0; i < 5; ++i) {
        ivec2 q = clamp(px + OFFSETS[i], ivec2(0), last);
        vec4 labels = texelFetch(u_labels, q, 0);  // a = 0 where no part was drawn
        // 1 - cos between the normals, the relative depth gap, and a nudge for the own pixel
        float cost = 1.0 - labels.a * dot(texelFetch(u_normals, q, 0).xyz, n)
                     + abs(labels.b - depth) / depth + (i == 0 ? 0.0 : 1e-5);
        best = cost < best_cost ? q : best;
        best_cost = min(cost, best_cost);
    }
    f_color = texelFetch(u_shaded, best, 0);
}
