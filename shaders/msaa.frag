#version 330 core
// The multisampled pass: each sample's surface (facing normal, linear depth), for
// msaa_resolve.frag. llvmpipe runs a multisampled pass's shader once per sample for every
// 4x4 block a triangle touches, hidden or not (no early depth rejection under MSAA), so this
// shader only writes what it interpolated; the lookups run once per pixel in the resolve.
in vec3 v_view_pos;
in vec3 v_normal;

layout(location = 0) out vec4 f_surface;  // facing normal, 1 where a surface covers the sample
layout(location = 1) out float f_depth;   // linear depth along the optical axis

#include "facing_normal.glsl"

void main() {
    f_surface = vec4(facing_normal(v_normal, normalize(-v_view_pos)), 1.0);
    f_depth = -v_view_pos.z;
}
