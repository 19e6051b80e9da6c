"""Config bounds live in each field's metadata and one validator reads them
(glsynth.core.checks.validate); the sections are Config's fields."""

import dataclasses
import re
import typing

import pytest

from glsynth.core.checks import RULE, Number
from glsynth.core.config import Config, DatasetConfig, FlightConfig, config_from_dict
from glsynth.core.errors import UserError

CHECKED_IN_CODE = {("damage", "severities"), ("damage", "spalling_severities"),
                   ("materials", "repository")}
"""Fields whose rule is code in __post_init__ (a list of names, a string), not a bound."""


def _sections() -> dict[str, type]:
    return {f.name: typing.get_type_hints(Config)[f.name] for f in dataclasses.fields(Config)}


def test_test_plates_are_bounded_by_plates():
    """A held-out split larger than the set it is held out of is refused, naming the bound."""
    assert DatasetConfig(n_plates=10, n_test_plates=10).n_test_plates == 10
    message = re.escape("dataset.n_test_plates = 11: must be in [0, 10]. Fix it in the "
                        "[dataset] table")
    with pytest.raises(UserError, match=message):
        DatasetConfig(n_plates=10, n_test_plates=11)
    with pytest.raises(UserError, match=r"dataset\.n_test_plates = 301: must be in \[0, 300\]"):
        config_from_dict({"dataset": {"n_plates": 300, "n_test_plates": 301}})


def test_a_bound_read_from_another_field_is_checked_after_that_field():
    """n_plates is checked first: a bad n_plates is named, not compared with."""
    with pytest.raises(UserError, match=r"dataset\.n_plates = -1"):
        DatasetConfig(n_plates=-1, n_test_plates=0)
    rule = next(f.metadata[RULE] for f in dataclasses.fields(DatasetConfig)
                if f.name == "n_test_plates")
    assert isinstance(rule, Number) and rule.hi(DatasetConfig(n_plates=7, n_test_plates=0)) == 7


def test_every_section_is_a_config_field_and_every_field_has_a_rule():
    sections = _sections()
    with pytest.raises(UserError, match=re.escape(f"allowed sections are {sorted(sections)}")):
        config_from_dict({"nosuchsection": {}})
    for name, cls in sections.items():
        if name == "design":  # StandardDesign bounds every field by its type
            continue
        hints = typing.get_type_hints(cls)
        bare = {(name, f.name) for f in dataclasses.fields(cls) if RULE not in f.metadata
                and typing.get_origin(hints[f.name]) is not typing.Literal}
        assert bare <= CHECKED_IN_CODE, bare


def test_a_list_field_checks_each_item():
    with pytest.raises(UserError, match=r"flight\.heights_m = \(\): must be a non-empty list"):
        FlightConfig(heights_m=())
    with pytest.raises(UserError, match=r"flight\.heights_m = -2\.0: must be in \[0\.0, 1000"):
        FlightConfig(heights_m=(1.0, -2.0))


def test_crack_widths_in_metres_and_their_bound_are_the_configs():
    from glsynth.appearance.cracks import MAX_WIDTH_M
    from glsynth.core.config import MAX_CRACK_WIDTH_MM, DamageConfig

    assert DamageConfig(crack_width_mm=(0.1, 2.0)).crack_width_m == (0.1 / 1e3, 2.0 / 1e3)
    assert MAX_WIDTH_M * 1e3 == MAX_CRACK_WIDTH_MM
    DamageConfig(crack_width_mm=(0.1, MAX_CRACK_WIDTH_MM))
    with pytest.raises(UserError, match=r"damage\.crack_width_mm = \(0\.1, 10\.5\)"):
        DamageConfig(crack_width_mm=(0.1, MAX_CRACK_WIDTH_MM + 0.5))
