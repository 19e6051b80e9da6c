"""What the camera model ([sensor], glsynth.render.camera_model) costs an inspection sample.

    .venv/bin/python bench/bench_camera_model.py [--env 0] [--cameras 8] [--rounds 3]

Opens environment --env of the inspection preset (seed 0) once and renders --cameras of its
cameras at full size, each round once as the render (photo=False: render and read back,
today's sample) and once photographed (the same render plus the camera model), the two in
turn so that a busy machine slows both alike. Reports the median seconds per view of each
and their ratio, and the camera model's own share. Writes bench/results/camera_model.json.
"""

import argparse
import statistics
import time

from common import write_results

from glsynth.core.config import load_config
from glsynth.render.view import EnvironmentView


def measure(env: int, n_cameras: int, rounds: int) -> dict:
    view = EnvironmentView.open(load_config("inspection"), 0, env)
    cameras = list(range(n_cameras))
    view.render(cameras[0])  # warm-up: shader compilation, first texture use
    times: dict[str, list[float]] = {"render": [], "photographed": [], "camera_model": []}
    for _ in range(rounds):
        for index in cameras:
            t0 = time.perf_counter()
            placement, output = view.render(index, photo=False)
            times["render"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            _, again = view.render(index, photo=False)
            t1 = time.perf_counter()
            view.photograph(again, placement.camera, index)
            t2 = time.perf_counter()
            times["photographed"].append(t2 - t0)
            times["camera_model"].append(t2 - t1)
    medians = {k: statistics.median(v) for k, v in times.items()}
    return {"env": env, "cameras": n_cameras, "rounds": rounds,
            "size": [view.config.render.width, view.config.render.height],
            "median_s": medians, "ratio": medians["photographed"] / medians["render"],
            "camera_model_share_of_render": medians["camera_model"] / medians["render"]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", type=int, default=0)
    p.add_argument("--cameras", type=int, default=8)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    write_results("camera_model", measure(args.env, args.cameras, args.rounds))


if __name__ == "__main__":
    main()
