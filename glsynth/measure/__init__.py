"""Measurements of the renderer: quality presets and their speed against accuracy."""
