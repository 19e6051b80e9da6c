// The two-sided shading normal: the mesh normal turned towards the viewer (open sheets such
// as the ground and the panels are seen from both sides). view_dir: unit, towards the eye.
vec3 facing_normal(vec3 normal, vec3 view_dir) {
    vec3 n = normalize(normal);
    return dot(n, view_dir) < 0.0 ? -n : n;
}
