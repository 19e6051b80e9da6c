"""The passes a render offers, in one registry: each pass's name (the name a viewer page asks
for), the renderer target it is read from, its RGB image and its legend. The renderer reads
which passes it draws from it, the viewer's frames their images and legends, and the viewer's
protocol the names a page may ask for."""

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from glsynth.core.filters import rrdr
from glsynth.core.labels import Component, Damage
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, depth_rgb, overlay

if TYPE_CHECKING:
    from glsynth.render.gl.renderer import RenderOutput

DEPTH_TICKS_M = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0)
"""The depth scale's marks; depth_rgb's log scale runs from the first to the last."""
CRACK_WIDTH_MAX_MM = 2.0
"""The crack-width colour scale's top: wider cracks take its colour."""
RRDR_RGB = np.array([(110, 110, 110), (40, 200, 80)], np.uint8)
"""Outside and inside the region of reliable damage recognition."""


@dataclass(frozen=True)
class Pass:
    image: Callable[["RenderOutput", float], np.ndarray]
    """(H, W, 3) uint8 of a render; the float is the camera's focal length in pixels."""
    legend: Callable[[], dict]
    """Swatches (label, rgb) of a label pass, a scale (value, rgb) of a continuous one."""
    target: Literal["labels", "color"] | None = None
    """The renderer target it is read back from; None: made of other passes."""
    offered: Callable[["RenderOutput"], bool] = lambda _: True
    """Whether a render has it (a renderer that draws no crack widths has no crack pass)."""


def crack_width_map(output: "RenderOutput") -> np.ndarray | None:
    """The render's crack widths in millimetres, where the renderer draws them."""
    return getattr(output, "crack_width", None)


def _swatches(names: list[str], colours: np.ndarray) -> list[dict]:
    return [{"label": n, "rgb": [int(c) for c in rgb]} for n, rgb in zip(names, colours)]


def _components() -> list[dict]:
    return _swatches([c.name.lower() for c in Component], COMPONENT_RGB)


def _damages(first: int = 0) -> list[dict]:
    names = [d.name.lower().replace("_", " ") for d in Damage]
    return _swatches(names[first:], DAMAGE_RGB[first:])


def _scale(values: np.ndarray, colours: np.ndarray, unit: str) -> dict:
    return {"scale": [{"value": float(v), "rgb": [int(c) for c in rgb]}
                      for v, rgb in zip(values, colours)], "unit": unit}


def _depth_legend() -> dict:
    ticks = np.array(DEPTH_TICKS_M, np.float32)
    return _scale(ticks, depth_rgb(ticks[None], ticks[0], ticks[-1] + 1e-3)[0],
                  "m (log scale)")


def _plasma(width_mm: np.ndarray) -> np.ndarray:
    """Crack widths on the crack-width scale, as uint8 RGB."""
    from matplotlib import colormaps

    rgb = colormaps["plasma"](np.clip(width_mm / CRACK_WIDTH_MAX_MM, 0, 1))[..., :3] * 255
    return rgb.round().astype(np.uint8)


def _crack_image(output: "RenderOutput", _: float) -> np.ndarray:
    width = crack_width_map(output)
    if width is None:
        raise ValueError("this renderer draws no crack widths")
    width = np.asarray(width, np.float32)
    dim = (output.color * 0.4).astype(np.uint8)
    return np.where((width > 0)[..., None], _plasma(width), dim)


def _labels_image(output: "RenderOutput", _: float) -> np.ndarray:
    comp = overlay(output.color, output.component, COMPONENT_RGB, 0.45)
    return overlay(comp, output.damage, DAMAGE_RGB, 0.8, skip=(Damage.NO_DAMAGE,))


def _rrdr_image(output: "RenderOutput", focal_px: float) -> np.ndarray:
    return overlay(output.color, rrdr(output.depth, focal_px).astype(np.uint8), RRDR_RGB, 0.5)


PASSES: dict[str, Pass] = {
    "color": Pass(lambda out, _: out.color, dict, "color"),
    "component": Pass(lambda out, _: COMPONENT_RGB[out.component],
                      lambda: {"swatches": _components()}, "labels"),
    "damage": Pass(lambda out, _: DAMAGE_RGB[out.damage], lambda: {"swatches": _damages()},
                   "labels"),
    "depth": Pass(lambda out, _: depth_rgb(out.depth, DEPTH_TICKS_M[0], DEPTH_TICKS_M[-1]),
                  _depth_legend, "labels"),
    "labels": Pass(_labels_image, lambda: {"swatches": _components() + _damages(2)}),
    "rrdr": Pass(_rrdr_image, lambda: {"swatches": _swatches(
        ["outside RRDR", "inside RRDR (>= 1.5 px/cm)"], RRDR_RGB)}),
    "crack_width": Pass(_crack_image, lambda: _scale(
        np.linspace(0, CRACK_WIDTH_MAX_MM, 5), _plasma(np.linspace(0, CRACK_WIDTH_MAX_MM, 5)),
        "mm"), offered=lambda out: crack_width_map(out) is not None),
}
"""Every pass by name, in the order a viewer lists them."""
DRAWN = frozenset(name for name, p in PASSES.items() if p.target is not None)
"""The passes a renderer draws (the others are made of them)."""
LABEL_PASSES = frozenset(name for name, p in PASSES.items() if p.target == "labels")
"""The passes read back from the label target."""
