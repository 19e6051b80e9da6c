"""What the viewer shows of one render: each pass as an RGB image, its legend, and the bytes
sent to the page (PNG for stills, lossless; JPEG while moving, small)."""

import cv2
import numpy as np

from glsynth.core.fileio import image_bytes
from glsynth.core.labels import Component, Damage
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, depth_rgb, overlay
from glsynth.data.filters import rrdr
from glsynth.render.gl.renderer import RenderOutput

DEPTH_TICKS_M = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0)
"""The depth scale's marks; depth_rgb's log scale runs from the first to the last."""
CRACK_WIDTH_MAX_MM = 2.0
"""The crack-width colour scale's top: wider cracks take its colour."""
RRDR_RGB = np.array([(110, 110, 110), (40, 200, 80)], np.uint8)
"""Outside and inside the region of reliable damage recognition."""
JPEG_QUALITY = 85


def crack_width_map(output: RenderOutput) -> np.ndarray | None:
    """The render's crack widths in millimetres, where the renderer draws them."""
    return getattr(output, "crack_width", None)


def available_passes(output: RenderOutput) -> list[str]:
    passes = ["color", "component", "damage", "depth", "labels", "rrdr"]
    return passes + (["crack_width"] if crack_width_map(output) is not None else [])


def _crack_rgb(output: RenderOutput) -> np.ndarray:
    from matplotlib import colormaps

    width = np.asarray(crack_width_map(output), np.float32)
    rgb = (colormaps["plasma"](np.clip(width / CRACK_WIDTH_MAX_MM, 0, 1))[..., :3] * 255)
    dim = (output.color * 0.4).astype(np.uint8)
    return np.where((width > 0)[..., None], rgb.round().astype(np.uint8), dim)


def pass_image(name: str, output: RenderOutput, focal_px: float) -> np.ndarray:
    """(H, W, 3) uint8 of pass ``name``; ``focal_px`` is the camera's, for the RRDR."""
    if name == "color":
        return output.color
    if name == "component":
        return COMPONENT_RGB[output.component]
    if name == "damage":
        return DAMAGE_RGB[output.damage]
    if name == "depth":
        return depth_rgb(output.depth, DEPTH_TICKS_M[0], DEPTH_TICKS_M[-1])
    if name == "labels":
        comp = overlay(output.color, output.component, COMPONENT_RGB, 0.45)
        return overlay(comp, output.damage, DAMAGE_RGB, 0.8, skip=(Damage.NO_DAMAGE,))
    if name == "rrdr":
        return overlay(output.color, rrdr(output.depth, focal_px).astype(np.uint8), RRDR_RGB,
                       0.5)
    if name == "crack_width":
        if crack_width_map(output) is None:
            raise ValueError("this renderer draws no crack widths")
        return _crack_rgb(output)
    raise ValueError(f"unknown pass {name!r}")


def _swatches(names: list[str], colours: np.ndarray) -> list[dict]:
    return [{"label": n, "rgb": [int(c) for c in rgb]} for n, rgb in zip(names, colours)]


def legend(name: str) -> dict:
    """Swatches (label, rgb) of a label pass, or a scale (value, rgb) of a continuous one."""
    components = [c.name.lower() for c in Component]
    damages = [d.name.lower().replace("_", " ") for d in Damage]
    if name in ("component", "labels"):
        return {"swatches": _swatches(components, COMPONENT_RGB)
                + (_swatches(damages[2:], DAMAGE_RGB[2:]) if name == "labels" else [])}
    if name == "damage":
        return {"swatches": _swatches(damages, DAMAGE_RGB)}
    if name == "rrdr":
        return {"swatches": _swatches(["outside RRDR", "inside RRDR (>= 1.5 px/cm)"],
                                      RRDR_RGB)}
    if name == "depth":
        ticks = np.array(DEPTH_TICKS_M, np.float32)
        colours = depth_rgb(ticks[None], ticks[0], ticks[-1] + 1e-3)[0]
        return {"scale": [{"value": float(t), "rgb": [int(c) for c in rgb]}
                          for t, rgb in zip(ticks, colours)], "unit": "m (log scale)"}
    if name == "crack_width":
        from matplotlib import colormaps

        values = np.linspace(0, CRACK_WIDTH_MAX_MM, 5)
        colours = (colormaps["plasma"](values / CRACK_WIDTH_MAX_MM)[:, :3] * 255).round()
        return {"scale": [{"value": float(v), "rgb": [int(c) for c in rgb]}
                          for v, rgb in zip(values, colours)], "unit": "mm"}
    return {}


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
