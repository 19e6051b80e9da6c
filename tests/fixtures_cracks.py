"""Fixtures the crack and spalling tests share, registered for every test module through
conftest's ``pytest_plugins``: one environment dressed under the mechanics damage model, built
once a session. Tests read it and never write into its damage bank's folder (copy it)."""

import dataclasses
from pathlib import Path

import pytest

from glsynth.appearance.damage_bank import DamageBank
from glsynth.appearance.dressing import Dressing, dress, open_repository
from glsynth.core.config import Config, DamageConfig, MaterialsConfig
from glsynth.world.environment import Environment, PartKind, build_environment

SMALL = dataclasses.replace(Config(), materials=MaterialsConfig(texture_size=32,
                                                                images_per_category=4))
"""The default config with a small texture repository."""
MECHANICS = dataclasses.replace(SMALL, damage=DamageConfig(resolution=64, model="mechanics"))
MECHANICS_SEED = 4


@dataclasses.dataclass(frozen=True)
class MechanicsDressing:
    config: Config
    env: Environment
    seen: frozenset[str]
    """Every other column: the dressing cracks and spalls only what a view sees."""
    dressing: Dressing
    bank_dir: Path
    """The damage bank's cache: a bank on a copy of it reads back what this one made."""


@pytest.fixture(scope="session")
def mechanics_dressing(tmp_path_factory) -> MechanicsDressing:
    """Environment 0 of seed MECHANICS_SEED under MECHANICS, every other column seen."""
    env = build_environment(MECHANICS, MECHANICS_SEED, 0)
    columns = [p for p in env.parts if p.kind is PartKind.COLUMN]
    seen = frozenset(p.name for p in columns[::2])
    bank_dir = tmp_path_factory.mktemp("mechanics-bank")
    dressing = dress(env, MECHANICS, open_repository(MECHANICS),
                     DamageBank(MECHANICS.damage, MECHANICS_SEED, cache_dir=bank_dir), set(seen))
    return MechanicsDressing(MECHANICS, env, seen, dressing, bank_dir)
