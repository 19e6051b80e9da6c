"""Label ids of the released Tokaido dataset (docs/design.md). 0 is 'unlabelled' in both sets."""

from enum import IntEnum


class Component(IntEnum):
    UNLABELLED = 0
    NONBRIDGE = 1
    SLAB = 2
    BEAM = 3
    COLUMN = 4
    NONSTRUCTURAL = 5  # poles, wires, fences
    RAIL = 6
    SLEEPER = 7
    OTHER = 8


class Damage(IntEnum):
    UNLABELLED = 0
    NO_DAMAGE = 1
    CONCRETE = 2
    REBAR = 3


COMPONENT_IDS = frozenset(int(c) for c in Component)
DAMAGE_IDS = frozenset(int(d) for d in Damage)
LABEL_MAPS: dict[str, type[IntEnum]] = {"component": Component, "damage": Damage}
"""The two label maps by the name the Tokaido layout, its manifests and the networks' tasks
give them."""
