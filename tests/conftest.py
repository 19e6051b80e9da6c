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
