"""Geometry without appearance: trajectories, meshes, environments, cameras, the sun and what
each camera can see. Pure numpy and trimesh; imports only glsynth.core."""
