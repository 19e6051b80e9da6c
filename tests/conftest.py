import dataclasses

import pytest

from glsynth.core.config import Config, EnvironmentConfig
from glsynth.world.environment import build_environment


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


SMALL = """
[dataset]
n_environments = 2
n_test_environments = 1
n_plates = 3
n_test_plates = 1
plates_per_task = 2
[cameras]
n_regular = 3
n_closeup = 2
[damage]
resolution = 64
[materials]
texture_size = 32
builtin_size = 64
images_per_category = 3
"""


@pytest.fixture(scope="session")
def small_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "small.toml"
    path.write_text(SMALL)
    return path


@pytest.fixture(scope="session")
def tiny_dataset(small_config, tmp_path_factory):
    """A generated Tokaido-format dataset: 2 environments x 5 cameras at 1920x1080, 3 plates
    (seed 5). Tests read it and never write into it."""
    from glsynth.cli import main

    out = tmp_path_factory.mktemp("tiny") / "ds"
    assert main(["generate", "--preset", "demo", "--config", str(small_config), "--seed", "5",
                 "--out", str(out)]) == 0
    return out
