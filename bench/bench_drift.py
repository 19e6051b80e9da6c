"""Memory drift of a generation worker at full size: one renderer opens --envs environments of
the paper preset in turn, --opens times in all, and renders --cameras views of each, as a
worker does. After each release the process returns its free memory (malloc_trim) and reads
its RSS. Readings of one environment's openings differ only by what leaked in between, so
the drift is the Theil-Sen slope of each environment's readings against the opening count
(the median of the slopes of all its pairs), reported per opening and per 10 environments,
over all openings after each environment's first and over the second half alone (whether
the process settles once its allocator has warmed up).

    .venv/bin/python bench/bench_drift.py [--preset paper] [--envs 2] [--opens 40]
                                          [--cameras 2]
"""

import argparse
import ctypes
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import load_config  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402


def rss_mib() -> float:
    """Resident memory after glibc hands its free memory back to the kernel."""
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def theil_sen(x: list[float], y: list[float]) -> float:
    return float(np.median([(y[j] - y[i]) / (x[j] - x[i])
                            for i in range(len(x)) for j in range(i + 1, len(x))]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--opens", type=int, default=40)
    parser.add_argument("--cameras", type=int, default=2)
    args = parser.parse_args()
    if args.opens < 4 * args.envs:
        parser.error(f"--opens {args.opens}: give at least 4 per environment "
                     f"({4 * args.envs}), so that the second half holds 2 of each")
    config = load_config(args.preset)
    renderer = Renderer(config.render)
    readings = []
    t0 = time.perf_counter()
    for k in range(args.opens):
        env = k % args.envs
        view = EnvironmentView.open(config, 0, env, renderer)
        for index in range(args.cameras):
            view.render(index)
        del view
        renderer.release_scene()
        readings.append({"opening": k, "environment": env, "rss_mib": round(rss_mib(), 1)})
        print(readings[-1], flush=True)
    renderer.release()
    slopes: dict[str, dict[str, float]] = {"all": {}, "second_half": {}}
    for env in range(args.envs):
        mine = [r for r in readings if r["environment"] == env][1:]  # after its first opening
        late = [r for r in mine if r["opening"] >= args.opens // 2]
        for name, part in (("all", mine), ("second_half", late)):
            slopes[name][str(env)] = round(
                theil_sen([r["opening"] for r in part], [r["rss_mib"] for r in part]), 3)
    write_results("drift", {
        "preset": args.preset, "environments": args.envs, "openings": args.opens,
        "cameras_per_opening": args.cameras, "seconds": round(time.perf_counter() - t0, 1),
        "readings": readings,
        "slope_mib_per_opening_by_environment": slopes,
        "growth_mib_per_10_environments": {
            name: round(10 * statistics.median(by_env.values()), 2)
            for name, by_env in slopes.items()}})


if __name__ == "__main__":
    main()
