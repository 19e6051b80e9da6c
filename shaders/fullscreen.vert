#version 330 core
// One triangle covering the whole viewport, from gl_VertexID alone (no vertex buffer), at the
// far plane: the sky draws it after the geometry with depth test <=, so it fills only where
// nothing was hit; the occlusion passes draw it with no depth test.
void main() {
    vec2 corner = vec2(float((gl_VertexID & 1) << 2), float((gl_VertexID & 2) << 1)) - 1.0;
    gl_Position = vec4(corner, 1.0, 1.0);
}
