"""What concrete detail costs a flight's frame: the same orbit frames rendered with
[materials] concrete_detail "off" and "on", alternately opened in one process.

    .venv/bin/python bench/bench_detail_cost.py [--standoff 4] [--size 960x540] [--every 10]
                                                [--repeats 2]

Paper preset, seed 0, environment 0, an orbit of column 4 (rings at 1.5 and 2.5 m, 50 mm
lens): every --every-th frame, after one unmeasured render; the median seconds a frame per
opening (bench/results/detail_cost.json).
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import config_from_dict, load_config  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402
from glsynth.world.flights import plan_flight  # noqa: E402


def frame_seconds(config, cameras, measured) -> float:
    view = EnvironmentView.open(config, 0, 0, cameras=cameras)
    with view.renderer:
        view.renderer.render(measured[0])  # compiles and warms the draw path
        times = []
        for camera in measured:
            t0 = time.perf_counter()
            view.renderer.render(camera)
            times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--standoff", type=float, default=4.0)
    p.add_argument("--size", default="960x540")
    p.add_argument("--every", type=int, default=10)
    p.add_argument("--repeats", type=int, default=2)
    args = p.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    base = config_from_dict({"render": {"width": width, "height": height}, "flight": {
        "column": 4, "standoff_m": args.standoff, "heights_m": [1.5, 2.5], "focal_mm": 50.0}},
        load_config("paper"))
    cameras = plan_flight(build_environment(base, 0, 0), base, validate=True).cameras(base)
    measured = cameras[::args.every]
    seconds: dict[str, list[float]] = {"off": [], "on": []}
    for _ in range(args.repeats):
        for mode in seconds:
            config = dataclasses.replace(base, materials=dataclasses.replace(
                base.materials, concrete_detail=mode))
            seconds[mode].append(frame_seconds(config, cameras, measured))
    write_results("detail_cost", {"setting": vars(args), "frames_measured": len(measured),
                                  "seconds_per_frame_median": seconds})
    return 0


if __name__ == "__main__":
    sys.exit(main())
