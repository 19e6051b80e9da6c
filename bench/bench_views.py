"""What the cameras see under each reading of the paper's camera placement ([cameras] placement
and height_from, docs/design.md): keep rates by camera
kind and removal reason (Section 3.4 filters), the share of kept views showing each component,
and component pixel shares, from colour, component and depth renders at preview size.

    .venv/bin/python bench/bench_views.py [--preset paper] [--envs 6] [--width 384]
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import HEIGHTS_FROM, PLACEMENTS, load_config  # noqa: E402
from glsynth.core.labels import Component  # noqa: E402
from glsynth.data.filters import removal_reason  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView, preview_config  # noqa: E402

CLASSES = [c for c in Component if c != Component.UNLABELLED]


def measure(config, envs: int) -> dict:
    kinds = {k: {"views": 0, "kept": 0, "removed": {}} for k in ("regular", "closeup")}
    shows = {k: {c.name.lower(): 0 for c in CLASSES} for k in kinds}
    pixels = np.zeros(len(Component), np.int64)
    renderer = Renderer(config.render)
    n = config.cameras.total
    for env in range(envs):
        view = EnvironmentView.open(config, 0, env, renderer)
        for index in range(n):
            placement, out = view.render(index, frozenset({"color", "component", "depth"}))
            k = kinds[placement.kind]
            k["views"] += 1
            reason = removal_reason(out.color, out.component, out.depth)
            if reason is not None:
                k["removed"][reason] = k["removed"].get(reason, 0) + 1
                continue
            k["kept"] += 1
            present = np.bincount(out.component.ravel(), minlength=len(Component))
            pixels += present
            for c in CLASSES:
                shows[placement.kind][c.name.lower()] += int(present[c] > 0)
    renderer.release()
    total = pixels[1:].sum()
    return {
        "keep_rate": {k: round(v["kept"] / v["views"], 4) for k, v in kinds.items()},
        "views": kinds,
        "share_of_kept_views_showing": {
            k: {c: round(v / max(1, kinds[k]["kept"]), 4) for c, v in s.items()}
            for k, s in shows.items()},
        "component_pixel_share": {c.name.lower(): round(float(pixels[c] / total), 4)
                                  for c in CLASSES},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--envs", type=int, default=6)
    parser.add_argument("--width", type=int, default=384)
    args = parser.parse_args()
    base = preview_config(load_config(args.preset), args.width)
    results = {"paper": {"keep_rate": {"regular": 0.8648, "closeup": 0.7288}},
               "envs": args.envs, "size": [base.render.width, base.render.height]}
    for placement in PLACEMENTS:
        for height_from in HEIGHTS_FROM:
            name = f"placement={placement}, height_from={height_from}"
            config = dataclasses.replace(base, cameras=dataclasses.replace(
                base.cameras, placement=placement, height_from=height_from))
            t0 = time.perf_counter()
            results[name] = measure(config, args.envs)
            results[name]["seconds"] = round(time.perf_counter() - t0, 1)
            print(name, results[name]["keep_rate"], {
                k: (v["rail"], v["sleeper"])
                for k, v in results[name]["share_of_kept_views_showing"].items()}, flush=True)
    write_results("views", results)


if __name__ == "__main__":
    main()
