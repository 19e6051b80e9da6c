"""Where the installed package data lives (an editable install and a wheel alike), and where
glsynth caches what it can make again."""

import os
from importlib import resources
from pathlib import Path


def shader_dir() -> Path:
    return Path(str(resources.files("glsynth.shaders")))


def cache_root() -> Path:
    """$GLSYNTH_CACHE, default ~/.cache/glsynth: the built-in texture repository, repository
    images decoded at a texture size, the damage bank and the resized training inputs."""
    return Path(os.environ.get("GLSYNTH_CACHE") or Path.home() / ".cache" / "glsynth")
