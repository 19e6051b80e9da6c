#version 330 core
// Shared by the colour and the label pass, so both see the same positions and UVs. The
// programs' crack and zone variants (#define CRACKS, SPALL) also pass on the mesh-frame
// position.
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
#if defined(CRACKS) || defined(SPALL)
out vec3 v_mesh_pos;   // the mesh's own frame, where its cracks and zones are given
#endif

void main() {
    vec4 view = u_modelview * vec4(in_position, 1.0);
    v_view_pos = view.xyz;
    v_normal = u_normal_matrix * in_normal;
    v_uv = in_uv;
#if defined(CRACKS) || defined(SPALL)
    v_mesh_pos = in_position;
#endif
    gl_Position = u_projection * view;
}
