"""Where the installed package data lives (an editable install and a wheel alike), and where
glsynth caches what it can make again."""

import os
from importlib import resources
from pathlib import Path

from glsynth.core.errors import UserError, named


def shader_dir() -> Path:
    return Path(str(resources.files("glsynth.shaders")))


def cache_root() -> Path:
    """$GLSYNTH_CACHE, default ~/.cache/glsynth: the built-in texture repository, repository
    images decoded at a texture size, the damage bank and the resized training inputs."""
    return Path(os.environ.get("GLSYNTH_CACHE") or Path.home() / ".cache" / "glsynth")


def cache_folder(folder: Path) -> Path:
    """``folder`` (under cache_root()) made where missing. What stands in its way is named as
    the cache's, $GLSYNTH_CACHE, with the fix; never as an --out folder's."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise cache_error(folder, err) from None
    return folder


def cache_error(path: Path, err: OSError) -> UserError:
    """The one-line error for ``path`` in the cache that cannot be made, named as the cache's
    with the fix."""
    where = "$GLSYNTH_CACHE" if os.environ.get("GLSYNTH_CACHE") else \
        "the cache folder (default ~/.cache/glsynth; $GLSYNTH_CACHE moves it)"
    return UserError(f"{where}: cannot make {named(path)} ({err.strerror}); remove what is in "
                     "its way, or point $GLSYNTH_CACHE at a writable folder")
