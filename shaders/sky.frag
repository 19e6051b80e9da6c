#version 330 core
// The background where no geometry was drawn: the sky in this pixel's viewing direction,
// through the shared tone map.
#include "tonemap.glsl"
#include "sky.glsl"

uniform vec4 u_intrinsics;      // fx, fy, cx, cy in pixels (image rows run top to bottom)
uniform float u_height;         // image height in pixels
uniform mat3 u_world_from_view;
uniform vec3 u_exposure;  // per channel: the exposure times the white balance

layout(location = 0) out vec4 f_color;
// The colour pass's second target under MSAA (its shading normals, for the resolve): GL leaves
// an output a shader does not write undefined, and llvmpipe wrote varying garbage there, NaN
// included, which made edge pixels beside the sky change from run to run. Sky: no normal.
layout(location = 1) out vec4 f_normal;

void main() {
    // Pixel centre (col, row) of the image, whose K has pixel centres at integers.
    float col = gl_FragCoord.x - 0.5, row = u_height - gl_FragCoord.y - 0.5;
    vec3 ray = vec3((col - u_intrinsics.z) / u_intrinsics.x,
                    -(row - u_intrinsics.w) / u_intrinsics.y, -1.0);
    f_normal = vec4(0.0);
    f_color = vec4(tone_map(sky_radiance(normalize(u_world_from_view * ray)) * u_exposure), 1.0);
}
