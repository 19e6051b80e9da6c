"""Concrete's colour and brightness in inspection views, before and after weathering and
metering (issue 39), beside real photographs of concrete; and what it costs a view.

    .venv/bin/python bench/bench_concrete_stats.py [--seed 11] [--env 0] [--cameras 8]
                                                    [--real FOLDER ...]

Renders the first --cameras cameras of the inspection preset's environment --env twice, one
view open at a time: "before" (the preset with [materials] concrete_detail = "flights",
weathering = false, [lighting] metering = "scene": concrete as it was) and "after" (the
preset). Per image: mean RGB, mean luma (Rec. 601 of the sRGB bytes) and the within-view
spread (the standard deviation of luma over the image), and the seconds of its render after
one unmeasured render. Each --real folder's images (any size; not in the repository) get the
same statistics. Writes bench/results/concrete_stats.json.
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

LUMA = np.array([0.299, 0.587, 0.114])
"""Rec. 601 luma weights of sRGB bytes (as JPEG's Y)."""


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


def render_views(config: Config, seed: int, env: int, cameras: list[int]) -> dict:
    view = EnvironmentView.open(config, seed, env)
    try:
        view.render(cameras[0])  # unmeasured: shader compilation, first texture uses
        stats, seconds = [], []
        for index in cameras:
            t0 = time.perf_counter()
            _, output = view.render(index)
            seconds.append(time.perf_counter() - t0)
            stats.append({"camera": index, **image_stats(output.color)})
    finally:
        view.renderer.release()
    return {"views": stats, "summary": summarise(stats),
            "render_s_median": round(float(np.median(seconds)), 3)}


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
    parser.add_argument("--real", nargs="*", default=[], type=Path)
    args = parser.parse_args()
    config = load_config("inspection")
    cameras = list(range(args.cameras))
    before = render_views(before_config(config), args.seed, args.env, cameras)
    after = render_views(config, args.seed, args.env, cameras)
    results = {"seed": args.seed, "env": args.env, "before": before, "after": after,
               "cost_ratio": round(after["render_s_median"] / before["render_s_median"], 3),
               "real": [folder_stats(f) for f in args.real]}
    write_results("concrete_stats", results)


if __name__ == "__main__":
    main()
