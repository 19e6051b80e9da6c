"""The viewer's message fields are its request dataclasses' (glsynth.view.protocol)."""

import dataclasses
import json

import pytest

from glsynth.core.errors import UserError
from glsynth.view.protocol import (
    LIGHTING_FIELDS,
    InspectRequest,
    LightingRequest,
    SceneRequest,
    parse_message,
)


def test_a_message_carries_exactly_its_requests_fields():
    scene = {"seed": 3, "env": 1, "quality": None, "config_toml": None}
    assert set(scene) == {f.name for f in dataclasses.fields(SceneRequest)}
    assert parse_message(json.dumps({"type": "scene", **scene})) == SceneRequest(**scene)
    assert parse_message(json.dumps({"type": "inspect", "x": 0.5, "y": 0.25})) == \
        InspectRequest(0.5, 0.25)
    values = dict.fromkeys(LIGHTING_FIELDS, 1.0)
    assert parse_message(json.dumps({"type": "lighting", **values})) == LightingRequest(values)
    with pytest.raises(UserError, match=r"scene message: missing field\(s\) \['seed'\]"):
        parse_message(json.dumps({"type": "scene", "env": 1, "quality": None,
                                  "config_toml": None}))
    with pytest.raises(UserError, match=r"inspect message: unknown field\(s\) \['z'\]"):
        parse_message(json.dumps({"type": "inspect", "x": 0.5, "y": 0.5, "z": 0.0}))


def test_the_schema_names_each_requests_fields():
    """SCHEMA gives each field its JSON types; its names are the request dataclasses' (a
    lighting message sends LIGHTING_FIELDS, held by LightingRequest as one dict)."""
    from glsynth.view.protocol import SCHEMA, Request

    kinds = ("camera", "pass", "inspect", "lighting", "scene", "save")
    assert tuple(SCHEMA) == kinds
    for kind, cls in zip(kinds, Request.__args__, strict=True):
        names = set(LIGHTING_FIELDS) if cls is LightingRequest else {
            f.name for f in dataclasses.fields(cls)}
        assert set(SCHEMA[kind]) == names, kind
