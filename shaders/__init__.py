"""GLSL sources, installed as the glsynth.shaders package; load them with glsynth.resources."""
