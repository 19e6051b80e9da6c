#version 330 core
// Shared by the colour and the label pass, so both see the same positions and UVs. The
// programs' zone variants (#define SPALL) also pass on the mesh-frame position, and their crack
// variants (#define CRACKS) the position relative to the crack grid's origin: subtracted here,
// before interpolation, since a girder's mesh frame is the world frame, hundreds of metres
// from its origin, where a float32 position is good to only 0.03-0.06 mm, as coarse as the
// thinnest crack (glsynth.render.cracks_index). The detail variants (#define DETAIL) pass on
// the position relative to the part's own origin and the mesh-frame normal, for the same
// reason (shaders/concrete_detail.glsl).
uniform mat4 u_modelview;     // camera-from-mesh, composed in float64 on the CPU
uniform mat4 u_projection;
uniform mat3 u_normal_matrix; // inverse transpose of u_modelview's 3x3

in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;

invariant gl_Position;  // the same depth in every program that draws with this shader
out vec3 v_view_pos;   // camera space
out vec3 v_normal;     // camera space
out vec2 v_uv;
#ifdef SPALL
out vec3 v_mesh_pos;   // the mesh's own frame, where its zones are given
#endif
#ifdef CRACKS
uniform vec3 u_crack_origin;  // the crack grid's lower corner, mesh frame
out vec3 v_crack_pos;  // mesh frame, relative to u_crack_origin
#endif
#ifdef DETAIL
uniform vec3 u_detail_origin;  // the part's box's lower corner, mesh frame
out vec3 v_detail_pos;   // mesh frame, relative to u_detail_origin
out vec3 v_detail_normal;  // mesh frame
#endif

void main() {
    vec4 view = u_modelview * vec4(in_position, 1.0);
    v_view_pos = view.xyz;
    v_normal = u_normal_matrix * in_normal;
    v_uv = in_uv;
#ifdef SPALL
    v_mesh_pos = in_position;
#endif
#ifdef CRACKS
    // Exact for positions within a factor 2 of the origin (Sterbenz), so the fragment reads
    // the vertices' float32 positions to their own rounding.
    v_crack_pos = in_position - u_crack_origin;
#endif
#ifdef DETAIL
    v_detail_pos = in_position - u_detail_origin;
    v_detail_normal = in_normal;
#endif
    gl_Position = u_projection * view;
}
