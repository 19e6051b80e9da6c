"""Where the installed package data lives (an editable install and a wheel alike)."""

from importlib import resources
from pathlib import Path


def shader_dir() -> Path:
    return Path(str(resources.files("glsynth.shaders")))
