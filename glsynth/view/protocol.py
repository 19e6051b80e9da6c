"""The messages a page may send to ``glsynth view``, checked before any work.

Each message is a JSON object with a ``type`` and exactly that type's fields. Anything else
(unknown types or fields, wrong types, values out of range, more than MAX_MESSAGE_BYTES) is
refused with one line naming the field, and the server renders nothing for it. No message
names a file: the server makes every name it writes, and a config file travels as its text.
"""

import json
import math
from dataclasses import dataclass

import numpy as np

from glsynth.core.errors import UserError
from glsynth.data.quality import QUALITY
from glsynth.render.passes import PASSES

MAX_MESSAGE_BYTES = 256 * 1024
"""Room for a config file's text; a camera message is about 400 bytes."""
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

_FIELDS = {kind: set(LIGHTING_FIELDS) if cls is LightingRequest else set(cls.__dataclass_fields__)
           for kind, cls in zip(("camera", "pass", "inspect", "lighting", "scene", "save"),
                                Request.__args__)}
"""Each message type's fields: its request's (a lighting message sends LIGHTING_FIELDS, each
a number, which LightingRequest holds as one dict)."""


def number_field(data: dict, key: str, low: float, high: float) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise UserError(f"{key} = {value!r}: must be a finite number")
    if not low <= value <= high:
        raise UserError(f"{key} = {value!r}: must be in [{low:g}, {high:g}]")
    return float(value)


def _integer(data: dict, key: str, high: int) -> int:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= high:
        raise UserError(f"{key} = {value!r}: must be an integer in [0, {high}]")
    return value


def rigid_pose(value: object) -> np.ndarray:
    """A 4x4 rigid transform: rows of numbers, an orthonormal right-handed rotation, the last
    row (0, 0, 0, 1) and a position within MAX_COORDINATE_M of the origin."""
    try:
        pose = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise UserError("pose: must be 4 rows of 4 numbers") from None
    if pose.shape != (4, 4) or not np.isfinite(pose).all():
        raise UserError("pose: must be 4 rows of 4 finite numbers")
    rotation = pose[:3, :3]
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
        raise UserError(f"quality = {quality!r}: choose one of {', '.join(QUALITY)}")
    if text is not None and (not isinstance(text, str) or len(text) > MAX_CONFIG_CHARS):
        raise UserError(f"config_toml: must be the text of a TOML file of at most "
                        f"{MAX_CONFIG_CHARS} characters")
    return SceneRequest(seed=_integer(data, "seed", MAX_SEED), env=_integer(data, "env", MAX_ENV),
                        quality=quality, config_toml=text)


def _build(kind: str, data: dict) -> Request:
    if kind == "camera":
        if not isinstance(data["moving"], bool):
            raise UserError(f"moving = {data['moving']!r}: must be true or false")
        return CameraRequest(pose=rigid_pose(data["pose"]), focal_mm=number_field(data, "focal_mm",
                                                                         *FOCAL_MM),
                             moving=data["moving"])
    if kind == "pass":
        if data["name"] not in PASS_NAMES:
            raise UserError(f"pass {data['name']!r}: choose one of {', '.join(PASS_NAMES)}")
        return PassRequest(data["name"])
    if kind == "inspect":
        return InspectRequest(number_field(data, "x", 0.0, 1.0), number_field(data, "y", 0.0, 1.0))
    if kind == "lighting":
        # Ranges are the [lighting] section's own, checked when the config is made.
        return LightingRequest({k: number_field(data, k, -1e6, 1e6) for k in LIGHTING_FIELDS})
    if kind == "scene":
        return _scene(data)
    return SaveRequest()


def parse_message(text: str | bytes) -> Request:
    """The request in one message from a page, or UserError saying what is wrong with it."""
    if len(text) > MAX_MESSAGE_BYTES:
        raise UserError(f"message of {len(text)} bytes: at most {MAX_MESSAGE_BYTES} are read")
    try:
        data = json.loads(text)
    except (ValueError, UnicodeDecodeError):
        raise UserError("message: not JSON") from None
    if not isinstance(data, dict) or data.get("type") not in _FIELDS:
        raise UserError(f"message: must be an object whose type is one of "
                        f"{', '.join(_FIELDS)}")
    kind = data.pop("type")
    given, wanted = set(data), _FIELDS[kind]
    if given != wanted:
        extra, missing = sorted(given - wanted), sorted(wanted - given)
        raise UserError(f"{kind} message: " + "; ".join(
            ([f"unknown field(s) {extra}"] if extra else [])
            + ([f"missing field(s) {missing}"] if missing else [])))
    return _build(kind, data)
