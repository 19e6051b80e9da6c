#version 330 core
// 4x4 box average of the raw occlusion: removes the 4x4 rotation pattern of ssao.frag.
uniform sampler2D u_raw;
out float f_ao;

void main() {
    ivec2 size = textureSize(u_raw, 0);
    ivec2 base = ivec2(gl_FragCoord.xy) - 2;
    float sum = 0.0;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x)
            sum += texelFetch(u_raw, clamp(base + ivec2(x, y), ivec2(0), size - 1), 0).r;
    f_ao = sum / 16.0;
}
