"""Shared helpers for benchmarks: timing medians and a results file that names its command."""

import argparse
import dataclasses
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from glsynth.core.config import Config, load_config

RESULTS = Path(__file__).resolve().parent / "results"
LUMA = np.array([0.299, 0.587, 0.114])
"""Rec. 601 luma weights of sRGB bytes (as JPEG's Y): the brightness the image statistics
report."""
JEMALLOC = "/usr/lib/x86_64-linux-gnu/libjemalloc.so.2"
JEMALLOC_CONF = "oversize_threshold:0,background_thread:true,dirty_decay_ms:-1,muzzy_decay_ms:-1"


def training_env(**changes: str) -> dict[str, str]:
    """The environment of a CPU training subprocess: jemalloc preloaded where installed, as the
    README advises (a full-size step is about 3x slower without it), plus ``changes``."""
    env = dict(os.environ, **changes)
    if Path(JEMALLOC).exists():
        env.update(LD_PRELOAD=JEMALLOC, MALLOC_CONF=JEMALLOC_CONF)
    return env


def time_calls(fn: Callable[[], object], repeats: int, warmup: int = 1) -> list[float]:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def summary(times: list[float]) -> dict[str, float]:
    return {"median_s": statistics.median(times), "min_s": min(times), "max_s": max(times),
            "n": len(times)}


def write_results(name: str, results: dict, quiet: bool = False) -> Path:
    """bench/results/<name>.json, with the command that made it and the machine; printed
    unless ``quiet``."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {"command": "python " + " ".join(sys.argv), "machine": platform.node(),
               "python": platform.python_version(), "processor": platform.processor(),
               "results": results}
    path.write_text(json.dumps(payload, indent=2) + "\n")
    if not quiet:
        print(json.dumps(payload, indent=2))
    return path


def preset_views(presets: tuple[str, ...] = ("paper",)) -> tuple[str, int, Config, list[int]]:
    """The setting that bench_passes, bench_shader_cost and bench_pass_cpu share, from --env
    (0), --cameras (8) and, where a bench offers more than the paper preset, --preset (one of
    ``presets``, the first by default): the preset's name, the environment (of seed 0), the
    preset with damage textures at 512 px (the paper preset's open is faster; the texture size
    barely changes the drawing), and the camera indices spread over it."""
    parser = argparse.ArgumentParser()
    if len(presets) > 1:
        parser.add_argument("--preset", default=presets[0], choices=presets)
    parser.add_argument("--env", type=int, default=0)
    parser.add_argument("--cameras", type=int, default=8)
    args = parser.parse_args()
    preset = getattr(args, "preset", presets[0])
    base = load_config(preset)
    base = dataclasses.replace(base, damage=dataclasses.replace(base.damage, resolution=512))
    step = max(1, base.cameras.total // args.cameras)
    return (preset, args.env, base,
            list(range(0, base.cameras.total, step))[:args.cameras])
