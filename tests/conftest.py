import dataclasses

import pytest

from glsynth.config import Config, EnvironmentConfig
from glsynth.environment import build_environment


def env_config(**environment) -> Config:
    """Default config with some [environment] fields replaced."""
    return dataclasses.replace(Config(), environment=EnvironmentConfig(**environment))


@pytest.fixture(scope="session")
def env0():
    return build_environment(Config(), root_seed=0, env_index=0)


@pytest.fixture(scope="session", autouse=True)
def isolated_cache(tmp_path_factory):
    """Texture repository and damage bank caches in a fresh folder for the test session."""
    import os

    previous = os.environ.get("GLSYNTH_CACHE")
    os.environ["GLSYNTH_CACHE"] = str(tmp_path_factory.mktemp("glsynth-cache"))
    yield
    if previous is None:
        os.environ.pop("GLSYNTH_CACHE", None)
    else:
        os.environ["GLSYNTH_CACHE"] = previous
