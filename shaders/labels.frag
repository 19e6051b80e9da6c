#version 330 core
// One draw writes component id, damage id and linear depth into one RGBA32F target, with no
// multisampling and no blending, so ids are exact. Damage ids come from the part's damage mask
// (an integer texture: nearest sampling by definition); parts without one are 1 (no damage).
// The crack variant (#define CRACKS, for views that show cracks) labels the pixels that a
// crack covers at the centre or whose footprint its centreline crosses as concrete damage
// (exposed rebar stays) and writes to a second target the crack's width in millimetres (0
// where no crack labels the pixel) and the share of the pixel that cracks cover, which the
// colour pass darkens by; a draw without cracks (u_has_cracks false) writes 0 there. The zone
// variant (#define SPALL, for parts whose damage material has zones) takes the damage mask only
// inside the zones and 1 (no damage) outside; cracks still label on top.
in vec3 v_view_pos;
in vec2 v_uv;
#ifdef SPALL
in vec3 v_mesh_pos;
#endif
#ifdef CRACKS
in vec3 v_crack_pos;  // mesh frame, relative to the crack grid's origin (mesh.vert)
#endif

uniform float u_component;
uniform bool u_has_damage_mask;
uniform usampler2D u_damage_mask;

layout(location = 0) out vec4 f_labels;

#ifdef SPALL
#include "zones.glsl"
#endif

#ifdef CRACKS
uniform bool u_has_cracks;
layout(location = 1) out vec2 f_crack;  // (width mm, coverage)
#include "cracks.glsl"
#endif

void main() {
    float damage = 1.0;
    if (u_has_damage_mask) damage = float(texture(u_damage_mask, v_uv).r);
#ifdef SPALL
    if (!in_zones(v_mesh_pos.z)) damage = 1.0;
#endif
#ifdef CRACKS
    vec3 dpdx = dFdx(v_crack_pos), dpdy = dFdy(v_crack_pos);
    CrackHit hit = CrackHit(0.0, 0.0, false);
    if (u_has_cracks) hit = crack_hit(v_crack_pos, dpdx, dpdy);
    damage = hit.labelled ? max(damage, 2.0) : damage;  // 2: concrete damage, 3: rebar
    f_crack = vec2(hit.width_mm, hit.coverage);
#endif
    // Depth along the optical axis, interpolated in camera space: linear and float32-exact,
    // unlike a value read back from the 24-bit z-buffer.
    f_labels = vec4(u_component, damage, -v_view_pos.z, 1.0);
}
