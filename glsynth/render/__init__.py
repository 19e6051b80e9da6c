"""Turning a dressed environment into images: the scene graph, the GL renderer (glsynth.render.gl,
the only package that touches OpenGL), the GL-free ray cast, glTF export and Blender Cycles."""
