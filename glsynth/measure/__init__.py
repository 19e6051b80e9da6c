"""Measurements of the renderer: the quality presets' speed against accuracy
(quality_bench) and glsynth against Blender Cycles (blender_bench)."""
