"""Rough cracks (issue 39): what an inspection-preset sample costs and how much of it the
cracks label, against a baseline checkout, side by side in one run.

    .venv/bin/python bench/bench_crack_paths.py --baseline OTHER/.venv/bin/python

OTHER is a checkout of the code before (its virtual environment with glsynth installed from
it). Each round runs this file's worker once in each interpreter, alternately (the machine's
load falls on both alike): environment 0 of the inspection preset (seed 11) opened, then
cameras 0 .. --cameras - 1 rendered at full size, each timed (the render of one sample,
packing its cracks when a view first shows them). Reported per side: the median sample time
over all rounds, and over the views that show cracks the share of crack pixels, the median
crack width in pixels (the crack-width map over the pixel's footprint) and how much darker
the crack pixels are than the surface beside them (median, and the views where it is under
10 %). Writes bench/results/crack_paths.json.
"""

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

SEED, ENV = 11, 0


def worker(cameras: int) -> dict:
    """Time and crack statistics of each camera's sample, in this interpreter's glsynth."""
    import glsynth
    from glsynth.core.config import load_config
    from glsynth.render.view import EnvironmentView

    config = load_config("inspection")
    view = EnvironmentView.open(config, SEED, ENV, None)
    views = []
    for index in range(cameras):
        start = time.perf_counter()
        placement, out = view.render(index)
        seconds = time.perf_counter() - start
        width = out.crack_width
        k = placement.camera.K
        px_mm = out.depth / k[0, 0] * 1e3  # a pixel's width on a fronto-parallel surface
        crack = width > 0
        views.append({"camera": index, "seconds": seconds, "crack_share": float(crack.mean()),
                      "widths_px": (width[crack] / px_mm[crack]).tolist(),
                      "darkening": darkening(out.color, crack)})
    return {"views": views, "glsynth": str(Path(glsynth.__file__).parent)}


def darkening(color: np.ndarray, crack: np.ndarray) -> float:
    """1 - the crack pixels' mean linear luminance over that of the pixels 2-4 px beside
    them: how much darker a crack looks than the surface round it (0 without cracks)."""
    from scipy import ndimage

    if not crack.any():
        return 0.0
    light = (color.astype(np.float64) / 255) ** 2.2 @ [0.2126, 0.7152, 0.0722]
    ring = ndimage.binary_dilation(crack, iterations=4) & ~ndimage.binary_dilation(crack,
                                                                                   iterations=1)
    return float(1 - light[crack].mean() / max(light[ring].mean(), 1e-9))


def side(views: list[dict]) -> dict:
    cracked = [v for v in views if v["crack_share"] > 0]
    widths = np.concatenate([v["widths_px"] for v in cracked]) if cracked else np.zeros(1)
    return {"median_sample_s": statistics.median(v["seconds"] for v in views),
            "samples": len(views), "views_with_cracks": len(cracked),
            "mean_crack_share_pct": 100 * float(np.mean([v["crack_share"] for v in cracked])),
            "median_crack_width_px": float(np.median(widths)),
            "median_darkening": statistics.median(v["darkening"] for v in cracked),
            "views_darkened_under_10pct": sum(v["darkening"] < 0.1 for v in cracked)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", help="python of the checkout to compare with")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--cameras", type=int, default=12)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.cameras)))
        return
    if not args.baseline:
        parser.error("--baseline: the python of the checkout to compare with")
    runs: dict[str, list[dict]] = {"baseline": [], "now": []}
    code: dict[str, str] = {}
    for _ in range(args.rounds):
        for name, python in (("baseline", args.baseline), ("now", sys.executable)):
            done = subprocess.run([python, __file__, "--worker", "--cameras", str(args.cameras)],
                                  check=True, capture_output=True, text=True)
            worker_out = json.loads(done.stdout.strip().splitlines()[-1])
            runs[name] += worker_out["views"]
            code[name] = worker_out["glsynth"]
    result = {name: side(views) for name, views in runs.items()}
    result["code"] = code
    result["time_ratio"] = result["now"]["median_sample_s"] / result["baseline"]["median_sample_s"]
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from common import write_results
    write_results("crack_paths", result)


if __name__ == "__main__":
    main()
