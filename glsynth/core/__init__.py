"""The bottom layer: configuration, the standard design's numbers, label ids, seeding, file
writing and small image helpers. Imports nothing else of glsynth."""
