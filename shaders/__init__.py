"""GLSL sources, installed as the glsynth.shaders package; glsynth.render.gl.programs loads
them (and expands their #include lines)."""
