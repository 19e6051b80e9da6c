// The inputs of the multisample resolve (msaa_interior.frag, msaa_resolve.frag).
uniform sampler2DMS u_sample_surface;  // msaa.frag's facing normal and coverage per sample
uniform sampler2DMS u_sample_depth;    // and its linear depth
// MSAA_SAMPLES: the samples per pixel, #defined by glsynth.render.gl.programs from [render] msaa.
uniform sampler2D u_labels;     // (component, damage, linear depth, hit) per pixel
uniform sampler2D u_normals;    // the single-sample pass's shading normal per pixel
uniform sampler2D u_shaded;     // its colour per pixel
