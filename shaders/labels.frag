#version 330 core
// One draw writes component id, damage id and linear depth into one RGBA32F target, with no
// multisampling and no blending, so ids are exact. Damage ids come from the part's damage mask
// (an integer texture: nearest sampling by definition); parts without one are 1 (no damage).
in vec3 v_view_pos;
in vec2 v_uv;

uniform float u_component;
uniform bool u_has_damage_mask;
uniform usampler2D u_damage_mask;

out vec4 f_labels;

void main() {
    float damage = 1.0;
    if (u_has_damage_mask) damage = float(texture(u_damage_mask, v_uv).r);
    // Depth along the optical axis, interpolated in camera space: linear and float32-exact,
    // unlike a value read back from the 24-bit z-buffer.
    f_labels = vec4(u_component, damage, -v_view_pos.z, 1.0);
}
