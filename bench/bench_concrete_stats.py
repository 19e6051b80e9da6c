"""Concrete's colour and brightness in inspection views, before and after weathering and
metering (issue 39), beside real photographs of concrete; and what it costs a view.

    .venv/bin/python bench/bench_concrete_stats.py [--seed 11] [--env 0] [--cameras 8]
                                                    [--repeats 3] [--real FOLDER ...]

Renders the first --cameras cameras of the inspection preset's environment --env under two
configs, both views open and their renders interleaved: "before" (the preset with
[materials] concrete_detail = "flights", weathering = false, [lighting] metering = "scene":
concrete as it was) and "after" (the preset). Per image: mean RGB, mean luma (Rec. 601 of
the sRGB bytes) and the within-view spread (the standard deviation of luma over the image).
Cost: each render --repeats times, the fastest of each camera; the ratio of their sums.
Each --real folder's images (any size; kept out of the repository) get the same statistics.
Writes bench/results/concrete_stats.json and concrete_stats.jpg (the first four views:
before above, after below).
"""

import argparse
import dataclasses
import io
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import LUMA, RESULTS, write_results  # noqa: E402

from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.core.fileio import atomic_write_bytes  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

FIGURE_VIEWS, THUMB = 4, (480, 270)
"""concrete_stats.jpg: the first views, one row per config, each shrunk to this size."""

def image_stats(rgb: np.ndarray) -> dict[str, float | list[float]]:
    pixels = rgb[..., :3].reshape(-1, 3).astype(np.float64)
    luma = pixels @ LUMA
    return {"mean_rgb": [round(float(v), 1) for v in pixels.mean(0)],
            "luma": round(float(luma.mean()), 1), "luma_spread": round(float(luma.std()), 1)}


def summarise(stats: list[dict]) -> dict:
    """Medians (and ranges) over images."""
    luma = [s["luma"] for s in stats]
    spread = [s["luma_spread"] for s in stats]
    return {"n": len(stats),
            "mean_rgb": [round(float(v), 1) for v in np.median([s["mean_rgb"] for s in stats],
                                                                axis=0)],
            "luma_median": float(np.median(luma)), "luma_range": [min(luma), max(luma)],
            "spread_median": float(np.median(spread)), "spread_range": [min(spread),
                                                                         max(spread)]}


def before_config(config: Config) -> Config:
    materials = dataclasses.replace(config.materials, concrete_detail="flights",
                                    weathering=False)
    lighting = dataclasses.replace(config.lighting, metering="scene")
    return dataclasses.replace(config, materials=materials, lighting=lighting)


def render_both(configs: dict[str, Config], seed: int, env: int, cameras: list[int],
                repeats: int) -> dict:
    """Each camera under each config, the configs' views open side by side and their renders
    interleaved, ``repeats`` times (the fastest counts: the machine's other load only ever
    slows a render), after one unmeasured render each."""
    views = {name: EnvironmentView.open(config, seed, env) for name, config in configs.items()}
    stats: dict[str, list] = {name: [] for name in views}
    best: dict[str, list] = {name: [] for name in views}
    thumbs: dict[str, list] = {name: [] for name in views}
    try:
        for view in views.values():
            view.render(cameras[0])  # shader compilation, first texture uses
        for index in cameras:
            seconds: dict[str, list] = {name: [] for name in views}
            images = {}
            for _ in range(repeats):
                for name, view in views.items():
                    t0 = time.perf_counter()
                    images[name] = view.render(index)[1].color
                    seconds[name].append(time.perf_counter() - t0)
            for name in views:
                best[name].append(min(seconds[name]))
                stats[name].append({"camera": index, **image_stats(images[name])})
                if len(thumbs[name]) < FIGURE_VIEWS:
                    thumbs[name].append(np.asarray(Image.fromarray(images[name]).resize(
                        THUMB, Image.Resampling.LANCZOS)))
    finally:
        for view in views.values():
            view.renderer.release()
    figure = np.concatenate([np.concatenate(thumbs[name], 1) for name in views], 0)
    jpeg = io.BytesIO()  # a photograph-like figure: a JPEG is a tenth of the PNG
    Image.fromarray(figure).save(jpeg, "JPEG", quality=85)
    atomic_write_bytes(RESULTS / "concrete_stats.jpg", jpeg.getvalue())
    return {name: {"views": stats[name], "summary": summarise(stats[name]),
                   "render_s": [round(t, 3) for t in best[name]]} for name in views}


def folder_stats(folder: Path) -> dict:
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in {".jpg", ".jpeg",
                                                                          ".png"})
    stats = [image_stats(np.asarray(Image.open(p).convert("RGB"))) for p in files]
    name = f"{folder.parent.name}/{folder.name}"  # a data set's images/ folder: its name
    return {"folder": name, "summary": summarise(stats) if stats else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--env", type=int, default=0)
    parser.add_argument("--cameras", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--real", nargs="*", default=[], type=Path)
    args = parser.parse_args()
    config = load_config("inspection")
    views = render_both({"before": before_config(config), "after": config}, args.seed,
                        args.env, list(range(args.cameras)), args.repeats)
    ratio = sum(views["after"]["render_s"]) / sum(views["before"]["render_s"])
    results = {"seed": args.seed, "env": args.env, "repeats": args.repeats, **views,
               "cost_ratio": round(ratio, 3), "real": [folder_stats(f) for f in args.real]}
    write_results("concrete_stats", results)


if __name__ == "__main__":
    main()
