"""A camera as JSON: what the viewer's "copy camera" gives and ``glsynth render --camera-json``
reads (render's own camera.json is accepted too: it holds the same keys and more)."""

from pathlib import Path

from glsynth.core.config import Config
from glsynth.core.errors import UserError, named
from glsynth.core.reading import MAX_JSON_BYTES, parse_json, read_bytes
from glsynth.view.protocol import FOCAL_MM, number_field, rigid_pose
from glsynth.world.cameras import Camera


def camera_json(camera: Camera) -> dict:
    """The pose and the focal length on the sensor: the view, at any image size."""
    return {"pose": camera.pose.tolist(), "focal_mm": camera.focal_mm,
            "sensor_mm": camera.sensor_mm}


def camera_from_json(data: object, config: Config) -> Camera:
    """The camera of ``data`` (``pose``, ``focal_mm``, optionally ``sensor_mm``) at the
    config's image size and depth range."""
    if not isinstance(data, dict) or not {"pose", "focal_mm"} <= set(data):
        raise UserError("camera JSON: must be an object with pose (4x4 world-from-camera) and "
                        "focal_mm, as the viewer's 'copy camera' gives")
    sensor = number_field(data, "sensor_mm", 1.0, 100.0) if "sensor_mm" in data \
        else config.cameras.sensor_mm
    r = config.render
    return Camera(r.width, r.height, number_field(data, "focal_mm", *FOCAL_MM), sensor,
                  rigid_pose(data["pose"]), r.znear_m, r.zfar_m)


def read_camera_json(path: str | Path, config: Config) -> Camera:
    """The camera of a JSON file, read as every glsynth JSON is (glsynth.data.readers)."""
    fix = "give a camera.json or the viewer's 'copy camera' JSON"
    what = f"--camera-json {named(path)}"
    data = parse_json(read_bytes(Path(path), "--camera-json", MAX_JSON_BYTES, fix), what, fix)
    try:
        return camera_from_json(data, config)
    except UserError as err:
        raise UserError(f"{what}: {err}") from None
