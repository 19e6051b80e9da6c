"""The texture repository (one folder per category), installed as glsynth.textures."""
