#version 330 core
// Screen-space ambient occlusion from the label pass's linear depth. Each pixel's camera-space
// position and normal are rebuilt from depth (the normal from the neighbour with the smaller
// depth step on each axis, so silhouettes do not bend it); u_samples points of a fixed
// cosine-weighted hemisphere of radius u_radius, turned by a 4x4 pattern of angles, are
// projected back, and a point is occluded where the surface seen there lies in front of it by
// more than a small bias and within the radius. ssao_blur.frag averages the 4x4 pattern away.
// An open plane sees only its own surface behind its samples: occlusion 0, output 1.
uniform sampler2D u_labels;   // (component, damage, linear depth, hit), GL rows bottom-up
uniform vec4 u_intrinsics;    // fx, fy, cx, cy in pixels (image rows top-down)
uniform vec2 u_size;          // width, height
uniform float u_radius;       // metres
uniform int u_samples;

out float f_ao;

const float GOLDEN = 2.39996323;

vec3 view_pos(vec2 frag, float d) {  // gl_FragCoord-style pixel position and depth
    float col = frag.x - 0.5, row = u_size.y - frag.y - 0.5;
    return vec3((col - u_intrinsics.z) / u_intrinsics.x * d,
                -(row - u_intrinsics.w) / u_intrinsics.y * d, -d);
}

vec2 to_frag(vec3 p) {
    float d = -p.z;
    float col = u_intrinsics.x * p.x / d + u_intrinsics.z;
    float row = u_intrinsics.w - u_intrinsics.y * p.y / d;
    return vec2(col + 0.5, u_size.y - row - 0.5);
}

float depth_at(vec2 frag) { return texelFetch(u_labels, ivec2(frag), 0).b; }

void main() {
    vec4 here = texelFetch(u_labels, ivec2(gl_FragCoord.xy), 0);
    if (here.a < 0.5) { f_ao = 1.0; return; }
    vec2 f = gl_FragCoord.xy;
    vec3 p = view_pos(f, here.b);
    vec3 px1 = view_pos(f + vec2(1, 0), depth_at(f + vec2(1, 0))) - p;
    vec3 px0 = p - view_pos(f - vec2(1, 0), depth_at(f - vec2(1, 0)));
    vec3 py1 = view_pos(f + vec2(0, 1), depth_at(f + vec2(0, 1))) - p;
    vec3 py0 = p - view_pos(f - vec2(0, 1), depth_at(f - vec2(0, 1)));
    vec3 dx = abs(px1.z) < abs(px0.z) ? px1 : px0;
    vec3 dy = abs(py1.z) < abs(py0.z) ? py1 : py0;
    vec3 n = normalize(cross(dx, dy));
    if (dot(n, p) > 0.0) n = -n;  // towards the camera
    vec3 t = normalize(abs(n.x) < 0.9 ? cross(n, vec3(1, 0, 0)) : cross(n, vec3(0, 1, 0)));
    vec3 b = cross(n, t);
    ivec2 cell = ivec2(gl_FragCoord.xy) & 3;
    float turn = float(cell.x * 4 + cell.y) * (6.28318531 / 16.0);
    float bias = 0.002 * here.b + 0.01;
    float occluded = 0.0;
    for (int i = 0; i < u_samples; ++i) {
        float u = (float(i) + 0.5) / float(u_samples);
        float r = sqrt(u);                        // cosine-weighted disc, lifted to the hemisphere
        float a = float(i) * GOLDEN + turn;
        float scale = mix(0.1, 1.0, u * u);       // more samples near the point
        vec3 k = vec3(r * cos(a), r * sin(a), sqrt(max(1.0 - u, 0.0))) * scale * u_radius;
        vec3 s = p + t * k.x + b * k.y + n * k.z;
        if (s.z >= -1e-3) continue;               // behind the camera: unknown, open
        vec2 g = to_frag(s);
        if (any(lessThan(g, vec2(0.0))) || any(greaterThanEqual(g, u_size))) continue;
        vec4 seen = texelFetch(u_labels, ivec2(g), 0);
        if (seen.a < 0.5) continue;               // sky
        float gap = -s.z - seen.b;                // > 0: the seen surface is in front of s
        if (gap > bias)
            occluded += smoothstep(0.0, 1.0, u_radius / max(here.b - seen.b, 1e-4));
    }
    f_ao = 1.0 - occluded / float(u_samples);
}
