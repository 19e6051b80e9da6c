"""What the viewer shows of one render: each pass as an RGB image and its legend (from the pass
registry, glsynth.render.passes), and the bytes sent to the page (PNG for stills, lossless;
JPEG while moving, small)."""

import cv2
import numpy as np

from glsynth.core.fileio import image_bytes
from glsynth.render.gl.renderer import RenderOutput
from glsynth.render.passes import PASSES

JPEG_QUALITY = 85


def available_passes(output: RenderOutput) -> list[str]:
    """The passes the page may show of ``output``, in the registry's order."""
    return [name for name, p in PASSES.items() if p.offered(output)]


def pass_image(name: str, output: RenderOutput, focal_px: float) -> np.ndarray:
    """(H, W, 3) uint8 of pass ``name``; ``focal_px`` is the camera's, for the RRDR."""
    if name not in PASSES:
        raise ValueError(f"unknown pass {name!r}")
    return PASSES[name].image(output, focal_px)


def legend(name: str) -> dict:
    """Swatches (label, rgb) of a label pass, or a scale (value, rgb) of a continuous one."""
    return PASSES[name].legend() if name in PASSES else {}


def encode(image: np.ndarray, still: bool) -> tuple[bytes, str]:
    """The image's bytes and MIME type: PNG (lossless, as the dataset's files) for a still,
    JPEG while moving."""
    if still:
        return image_bytes(image), "image/png"
    bgr = np.ascontiguousarray(image[..., ::-1])
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise RuntimeError(f"OpenCV could not encode a {image.shape} image")
    return data.tobytes(), "image/jpeg"
