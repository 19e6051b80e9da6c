"""Where the colour pass goes at 1920x1080: its median time with each costly feature turned off
in turn (MSAA, sky-visibility maps, shadows).

    .venv/bin/python bench/bench_passes.py [--env 0] [--cameras 8]

Paper preset, damage textures at 512 px (the open is faster; the texture size barely changes
the drawing), one environment, the same cameras for every variant. "color" renders colour
alone, which includes the label pass that the colour pass tests against.
"""

import dataclasses
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import preset_views, write_results  # noqa: E402

from glsynth.core.config import Config  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

VARIANTS = {
    "paper preset (MSAA 4, 16 sky maps, 2048 px shadows)": {},
    "MSAA 0": {"msaa": 0},
    # Whether MSAA multiplies the shading (per-sample) or only the raster work: the sky
    # lookups' cost with and without it.
    "no sky maps": {"sky_visibility_maps": 0},
    "no sky maps, no shadows": {"sky_visibility_maps": 0, "shadow_map_px": 0},
    "MSAA 0, no shadows": {"msaa": 0, "shadow_map_px": 0},
    "MSAA 0, 4 sky maps": {"msaa": 0, "sky_visibility_maps": 4},
    "MSAA 0, no sky maps": {"msaa": 0, "sky_visibility_maps": 0},
    "MSAA 0, no sky maps, no shadows": {"msaa": 0, "sky_visibility_maps": 0,
                                        "shadow_map_px": 0},
}
PASSES = {"all": frozenset({"color", "component", "damage", "depth"}),
          "color": frozenset({"color"}),
          "labels and depth": frozenset({"component", "damage", "depth"})}


def variant(base: Config, **render: object) -> Config:
    return dataclasses.replace(base, render=dataclasses.replace(base.render, **render))


def timings(view: EnvironmentView, cameras: list[int]) -> dict[str, float]:
    view.render(cameras[0])  # compiles llvmpipe's shader variants
    out = {}
    for name, passes in PASSES.items():
        times = []
        for index in cameras:
            t0 = time.perf_counter()
            view.render(index, passes)
            times.append(time.perf_counter() - t0)
        out[f"{name}_ms_median"] = round(1e3 * statistics.median(times), 1)
    return out


def main() -> None:
    _, env, base, cameras = preset_views()
    results: dict = {"environment": env, "cameras": cameras, "variants": {}}
    for name, render in VARIANTS.items():
        config = variant(base, **render)
        view = EnvironmentView.open(config, 0, env, Renderer(config.render))
        results["variants"][name] = timings(view, cameras)
        view.renderer.release()
    write_results("passes", results)


if __name__ == "__main__":
    main()
