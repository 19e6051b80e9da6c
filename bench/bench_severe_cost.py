"""What open fences and severe damage as geometry cost a demo-preset sample: one environment
opened (built, dressed, uploaded) and all its cameras rendered, with [environment] fences and
[damage] geometry as before issue 40 ("solid", false) and as the demo preset sets them
("open", true), alternately in one process.

    .venv/bin/python bench/bench_severe_cost.py [--env 0] [--repeats 1] [--size 1920x1080]

Demo preset, seed 0, after one unmeasured sample: the seconds to open the environment and to
render its cameras (the render before the camera model, which neither setting changes), the
parts and triangles uploaded, per repeat and setting (bench/results/severe_cost.json).
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config, config_from_dict, load_config  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

SETTINGS = {"before": ("solid", False), "after": ("open", True)}


def _with(config: Config, fences: str, geometry: bool) -> Config:
    return dataclasses.replace(
        config, environment=dataclasses.replace(config.environment, fences=fences),
        damage=dataclasses.replace(config.damage, geometry=geometry))


def sample_seconds(config: Config, env: int) -> dict[str, float]:
    """Open environment ``env`` and render each of its cameras once."""
    t0 = time.perf_counter()
    view = EnvironmentView.open(config, 0, env)
    opened = time.perf_counter() - t0
    with view.renderer:
        for index in range(config.cameras.total):
            view.render(index, photo=False)
    parts = view.environment.parts
    return {"open_s": opened, "sample_s": time.perf_counter() - t0, "parts": len(parts),
            "triangles": sum(len(p.mesh.faces) for p in parts)}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", type=int, default=0)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--size", default="1920x1080")
    args = p.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    demo = config_from_dict({"render": {"width": width, "height": height}},
                            load_config("demo"))
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in SETTINGS}
    # Unmeasured: the first opening fills the process's caches (repository, damage bank).
    sample_seconds(_with(demo, *SETTINGS["after"]), args.env)
    for _ in range(args.repeats):
        for name, (fences, geometry) in SETTINGS.items():
            runs[name].append(sample_seconds(_with(demo, fences, geometry), args.env))
    ratio = (sum(r["sample_s"] for r in runs["after"])
             / sum(r["sample_s"] for r in runs["before"]))
    write_results("severe_cost", {"setting": vars(args), "cameras": demo.cameras.total,
                                  "runs": runs, "after_over_before": round(ratio, 3)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
