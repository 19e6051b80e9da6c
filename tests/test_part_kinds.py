"""A part's kind, not its name, says what it is (glsynth.world.environment.PartKind)."""

import re
from pathlib import Path

from glsynth.core.labels import Component
from glsynth.world.environment import BOX_BEAMS, OPEN_KINDS, PartKind

ROOT = Path(__file__).resolve().parents[1]
NAME_TEST = re.compile(r"""(?<!\.parent)\.(name|member)"""
                       r"""(\.(startswith|endswith|split)\(|\[-?\d+\])"""
                       r"""|\bin \w+\.(name|member)\b|"_(cross|tie|girder|wire)_\"""")
"""A part or member name read for what the part is: a prefix, a suffix, a word, a letter
(a folder's name, .parent.name, is no part's)."""


def test_no_module_reads_a_part_kind_from_its_name():
    found = [f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
             for folder in ("glsynth", "model", "bench") for path in (ROOT / folder).rglob("*.py")
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if NAME_TEST.search(line)]
    assert not found, found


def test_every_kind_has_one_component_and_the_groups_hold_what_they_say():
    assert {k.component for k in PartKind} == set(Component) - {Component.UNLABELLED}
    assert {k.component for k in BOX_BEAMS} == {Component.BEAM} and PartKind.GIRDER \
        not in BOX_BEAMS
    assert {k.component for k in OPEN_KINDS} == {Component.NONBRIDGE}
