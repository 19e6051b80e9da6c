"""The messages a page may send to ``glsynth view``, checked before any work.

Each message is a JSON text holding an object with a ``type`` and exactly that type's fields,
each of the JSON type SCHEMA gives. The checks run in order, each before anything that could
fail on what it lets through: the size (MAX_MESSAGE_BYTES), the nesting depth (MAX_DEPTH,
counted on the text, so no parser recurses deeper), the JSON syntax, the JSON type of every
field (before a value is hashed, looked up or converted), then ranges and shapes. Anything
else is refused with one line (UserError) naming the field, and the server renders nothing
for it. No message names a file: the server makes every name it writes, and a config file
travels as its text (what that text may change: glsynth.view.scene).
"""

import itertools
import json
import math
import re
from dataclasses import dataclass

import numpy as np

from glsynth.core.errors import UserError, shown
from glsynth.data.quality import QUALITY
from glsynth.render.passes import PASSES

MAX_MESSAGE_BYTES = 256 * 1024
"""Room for a config file's text; a camera message is about 400 bytes."""
MAX_DEPTH = 3
"""Nesting of arrays and objects: a camera message's pose (object, rows, numbers) is the
deepest."""
MAX_CONFIG_CHARS = 200_000
FOCAL_MM = (4.0, 800.0)
"""Focal lengths a page may ask for, on the 36 mm sensor (a 4 mm lens sees 154 degrees)."""
MAX_COORDINATE_M = 100_000.0
MAX_SEED = 2 ** 32 - 1
MAX_ENV = 1_000_000
PASS_NAMES = tuple(PASSES)
LIGHTING_FIELDS = ("sun_elevation_deg", "sun_azimuth_deg", "turbidity", "exposure")


@dataclass(frozen=True)
class CameraRequest:
    pose: np.ndarray
    """4x4 world-from-camera (camera looks down -z, +y up), rotation orthonormal."""
    focal_mm: float
    moving: bool
    """True while the camera moves (a small, fast frame); False for the full-size still."""


@dataclass(frozen=True)
class PassRequest:
    name: str


@dataclass(frozen=True)
class InspectRequest:
    x: float
    """Across the image, 0 at the left edge, 1 at the right."""
    y: float
    """Down the image, 0 at the top edge, 1 at the bottom."""


@dataclass(frozen=True)
class LightingRequest:
    values: dict[str, float]
    """Each of LIGHTING_FIELDS: a fixed value for its [lighting] range."""


@dataclass(frozen=True)
class SceneRequest:
    seed: int
    env: int
    quality: str | None
    config_toml: str | None
    """The text of a config file overlaid on the preset; None: none."""


@dataclass(frozen=True)
class SaveRequest:
    pass


Request = (CameraRequest | PassRequest | InspectRequest | LightingRequest | SceneRequest
           | SaveRequest)

NUMBER, INTEGER, BOOLEAN, STRING, NULL, ARRAY = "number", "integer", "boolean", "string", \
    "null", "array"
SCHEMA: dict[str, dict[str, tuple[str, ...]]] = {
    "camera": {"pose": (ARRAY,), "focal_mm": (NUMBER,), "moving": (BOOLEAN,)},
    "pass": {"name": (STRING,)},
    "inspect": {"x": (NUMBER,), "y": (NUMBER,)},
    "lighting": {name: (NUMBER,) for name in LIGHTING_FIELDS},
    "scene": {"seed": (INTEGER,), "env": (INTEGER,), "quality": (STRING, NULL),
              "config_toml": (STRING, NULL)},
    "save": {},
}
"""Each message type's fields and the JSON types each may take (an integer is a number)."""
_TOKENS = re.compile(r'"(?:[^"\\]|\\[\s\S]?)*"?|[\[\]{}]')
"""A JSON string (to its closing quote or the end of the text: every match succeeds, so the
scan is linear) or a bracket."""
_NESTING = {"[": 1, "{": 1, "]": -1, "}": -1}


def json_type(value: object) -> str:
    """The JSON type of a value json.loads gives ("integer" for whole numbers)."""
    if value is None:
        return NULL
    if isinstance(value, bool):
        return BOOLEAN
    if isinstance(value, int):
        return INTEGER
    return {float: NUMBER, str: STRING, list: ARRAY, dict: "object"}[type(value)]


def number_field(data: dict, key: str, low: float, high: float) -> float:
    value = data[key]
    # A float is checked for finiteness; an integer of any size compares exactly below.
    if json_type(value) not in (NUMBER, INTEGER) or isinstance(value, float) and not \
            math.isfinite(value):
        raise UserError(f"{key} = {shown(value, 40)}: must be a finite number")
    if not low <= value <= high:
        raise UserError(f"{key} = {shown(value, 40)}: must be in [{low:g}, {high:g}]")
    return float(value)


def _integer(data: dict, key: str, high: int) -> int:
    value = data[key]
    if json_type(value) != INTEGER or not 0 <= value <= high:
        raise UserError(f"{key} = {shown(value, 40)}: must be an integer in [0, {high}]")
    return value


def rigid_pose(value: object) -> np.ndarray:
    """A 4x4 rigid transform: rows of numbers, an orthonormal right-handed rotation, the last
    row (0, 0, 0, 1) and a position within MAX_COORDINATE_M of the origin."""
    if (json_type(value) != ARRAY or len(value) != 4
            or any(json_type(row) != ARRAY or len(row) != 4
                   or any(json_type(v) not in (NUMBER, INTEGER) for v in row) for row in value)):
        raise UserError("pose: must be 4 rows of 4 numbers")
    try:
        pose = np.array(value, dtype=np.float64)
    except OverflowError:  # an integer too large for a float
        raise UserError("pose: must be 4 rows of 4 finite numbers") from None
    if not np.isfinite(pose).all():
        raise UserError("pose: must be 4 rows of 4 finite numbers")
    rotation = pose[:3, :3]
    # A mirror (det -1) is orthonormal too, but would render the scene flipped, with every
    # triangle's winding reversed.
    if (np.abs(rotation @ rotation.T - np.eye(3)).max() > 1e-6
            or np.linalg.det(rotation) < 0 or np.abs(pose[3] - (0, 0, 0, 1)).max() > 0):
        raise UserError("pose: the rotation must be orthonormal and right-handed, the last row "
                        "0 0 0 1")
    if np.abs(pose[:3, 3]).max() > MAX_COORDINATE_M:
        raise UserError(f"pose: the position must be within {MAX_COORDINATE_M:g} m of the "
                        "origin")
    return pose


def _scene(data: dict) -> SceneRequest:
    quality, text = data["quality"], data["config_toml"]
    if quality is not None and quality not in QUALITY:
        raise UserError(f"quality = {shown(quality, 40)}: choose one of {', '.join(QUALITY)}")
    if text is not None and len(text) > MAX_CONFIG_CHARS:
        raise UserError(f"config_toml: must be the text of a TOML file of at most "
                        f"{MAX_CONFIG_CHARS} characters")
    return SceneRequest(seed=_integer(data, "seed", MAX_SEED), env=_integer(data, "env", MAX_ENV),
                        quality=quality, config_toml=text)


def _build(kind: str, data: dict) -> Request:
    """The request of a message whose fields have their JSON types."""
    if kind == "camera":
        return CameraRequest(pose=rigid_pose(data["pose"]), focal_mm=number_field(data, "focal_mm",
                                                                         *FOCAL_MM),
                             moving=data["moving"])
    if kind == "pass":
        if data["name"] not in PASS_NAMES:
            raise UserError(f"pass {shown(data['name'], 40)}: choose one of "
                            f"{', '.join(PASS_NAMES)}")
        return PassRequest(data["name"])
    if kind == "inspect":
        return InspectRequest(number_field(data, "x", 0.0, 1.0), number_field(data, "y", 0.0, 1.0))
    if kind == "lighting":
        # Ranges are the [lighting] section's own, checked when the config is made.
        return LightingRequest({k: number_field(data, k, -1e6, 1e6) for k in LIGHTING_FIELDS})
    if kind == "scene":
        return _scene(data)
    return SaveRequest()


def _depth(text: str) -> int:
    """How deep arrays and objects nest in a JSON text (brackets inside strings are not
    counted), found without parsing it."""
    steps = (_NESTING.get(token, 0) for token in _TOKENS.findall(text))
    return max(itertools.accumulate(steps, initial=0))


def _names(keys: list[str]) -> str:
    """A message's field names, as many as fit one short line."""
    listed = ", ".join(shown(k, 30) for k in keys[:3])
    return f"[{listed}]" + (f" and {len(keys) - 3} more" if len(keys) > 3 else "")


def _check_fields(kind: str, data: dict) -> None:
    """Exactly ``kind``'s fields, each of a JSON type SCHEMA allows."""
    wanted = SCHEMA[kind]
    extra, missing = sorted(set(data) - set(wanted)), sorted(set(wanted) - set(data))
    if extra or missing:
        raise UserError(f"{kind} message: " + "; ".join(
            ([f"unknown field(s) {_names(extra)}"] if extra else [])
            + ([f"missing field(s) {_names(missing)}"] if missing else [])))
    for key, allowed in wanted.items():
        found = json_type(data[key])
        if found not in allowed and not (found == INTEGER and NUMBER in allowed):
            raise UserError(f"{kind} message: {key} = {shown(data[key], 40)} is a JSON "
                            f"{found}; it must be a JSON {' or '.join(allowed)}")


def parse_message(text: str | bytes) -> Request:
    """The request in one message from a page, or UserError saying what is wrong with it."""
    if not isinstance(text, str):
        raise UserError("message: a binary message; send the JSON as a text message")
    if len(text) > MAX_MESSAGE_BYTES:
        raise UserError(f"message of {len(text)} characters: at most {MAX_MESSAGE_BYTES} are "
                        "read")
    if _depth(text) > MAX_DEPTH:
        raise UserError(f"message: arrays and objects nest deeper than {MAX_DEPTH}")
    try:
        data = json.loads(text)
    except ValueError:
        raise UserError("message: not JSON") from None
    kind = data.pop("type", None) if isinstance(data, dict) else None
    if not isinstance(kind, str) or kind not in SCHEMA:
        raise UserError(f"message: must be an object whose type is one of {', '.join(SCHEMA)}")
    _check_fields(kind, data)
    return _build(kind, data)
