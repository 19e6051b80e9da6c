"""Each occlusion knob's time and colour error, in one run: the default preset's views rendered
with the default knobs, then with one knob at a time changed (SSAO on; the sky-visibility maps
off), all scored against one Cycles reference of the same views (same sun and sky for every
row).
Time per sample = median render + environment opening (the sky-visibility maps are baked
there) / cameras per environment. Needs Blender.

    .venv/bin/python bench/bench_lighting.py [--preset demo] [--cameras 3] [--samples 128]
"""

import argparse
import dataclasses
import shutil
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, write_results  # noqa: E402

from glsynth.core.config import config_from_dict, load_config  # noqa: E402
from glsynth.core.images import nearest_resize  # noqa: E402
from glsynth.measure.quality_bench import area_resize, colour_scores, spread_cameras  # noqa: E402
from glsynth.render.cycles import (  # noqa: E402
    cycles_seed,
    display,
    render_linear,
    require_blender,
)
from glsynth.render.view import EnvironmentView  # noqa: E402

SIZE = (480, 270)
VARIANTS = {
    "default (sky maps + SH, SSAO off)": {},
    "SSAO on": {"render": {"ao": "ssao"}},
    "sky visibility maps off": {"render": {"sky_visibility_maps": 0}},
}


def run(config, cameras: list[int], samples: int, blender: str) -> dict:
    t0 = time.perf_counter()
    view = EnvironmentView.open(config, 0, 0)
    open_s = time.perf_counter() - t0
    try:
        view.render(cameras[0])
        times, images, components, placements = [], [], [], []
        for index in cameras:
            t = time.perf_counter()
            placement, out = view.render(index)
            times.append(time.perf_counter() - t)
            images.append(area_resize(out.color, SIZE))
            components.append(nearest_resize(out.component, SIZE[::-1]))
            placements.append(placement)
        reference = None
        if samples:
            parts = [p for p in view.environment.parts if p.name in view.scene.parts]
            cams = [dataclasses.replace(p.camera, width=SIZE[0], height=SIZE[1])
                    for p in placements]
            result = render_linear(parts, view.dressing.materials, view.lighting, cams,
                                   [cycles_seed(0, 0, i) for i in cameras], samples,
                                   RESULTS / "lighting_work", blender)
            reference = [display(x, view.lighting) for x in result.linear]
    finally:
        view.renderer.release()
    render_s = statistics.median(times)
    return {"render_s": render_s, "open_s": open_s,
            "time_per_sample_s": render_s + open_s / config.cameras.total,
            "images": images, "components": components, "reference": reference}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="demo")
    parser.add_argument("--cameras", type=int, default=3)
    parser.add_argument("--samples", type=int, default=128)
    args = parser.parse_args()
    blender = require_blender()
    base = load_config(args.preset)
    cameras = spread_cameras(base.cameras.total, args.cameras)
    results = {"cameras": cameras, "size": list(SIZE), "reference_samples": args.samples,
               "rows": {}}
    reference = None
    for name, change in VARIANTS.items():
        config = config_from_dict(change, base)
        got = run(config, cameras, args.samples if reference is None else 0, blender)
        reference = reference or got["reference"]
        scores = [colour_scores(i, r, c) for i, r, c in
                  zip(got["images"], reference, got["components"])]
        results["rows"][name] = {"render_s": got["render_s"], "open_s": got["open_s"],
                                 "time_per_sample_s": got["time_per_sample_s"],
                                 "ciede2000": statistics.median(s["ciede2000"] for s in scores),
                                 "psnr_db": statistics.median(s["psnr_db"] for s in scores)}
        print(name, results["rows"][name], flush=True)
    shutil.rmtree(RESULTS / "lighting_work", ignore_errors=True)
    write_results("lighting", results)


if __name__ == "__main__":
    main()
