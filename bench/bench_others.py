"""Others (class 8) in a demo-preset dataset, and what they cost: the share of kept views that
show class 8, and the wall time of the same run with the others off (every [environment]
*_probability 0, the code path of the paper preset) and on (the demo preset's).

    .venv/bin/python bench/bench_others.py [--envs 10]

    .venv/bin/python bench/bench_others.py --cost 4

The first runs `glsynth generate --preset demo` twice with --envs environments (no test
split, no plates) in fresh folders with warm caches, off first, and writes
bench/results/others.json. The machine is shared, so those wall times drift with its load;
the second measures the cost as CPU time (this process and its threads), off and on in turn
for each environment: open it (build, dress, upload) and render and photograph its 12
cameras. It writes bench/results/others_cost.json.
"""

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.core.labels import Component  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

RULES = ("jacket_probability", "brace_probability", "downpipe_probability",
         "trough_probability", "sign_probability")


def generate(out: Path, config: Path) -> dict:
    subprocess.run([sys.executable, "-m", "glsynth", "generate", "--preset", "demo",
                    "--config", str(config), "--seed", "0", "--out", str(out)],
                   check=True, stderr=subprocess.DEVNULL)
    return json.loads((out / "report.json").read_text())


def class_8(root: Path) -> dict:
    """Kept views (files_train.csv) that show class 8, and its share of their pixels."""
    rows = [line.split(",") for line in (root / "files_train.csv").read_text().splitlines()
            if line]
    shown, pixels, total = 0, 0, 0
    for row in rows:
        labels = np.asarray(Image.open(root / row[1]))
        count = int((labels == Component.OTHER).sum())
        shown += count > 0
        pixels += count
        total += labels.size
    return {"kept_views": len(rows), "views_with_class_8": shown,
            "share_of_kept_views": round(shown / max(1, len(rows)), 4),
            "class_8_pixel_share": round(pixels / max(1, total), 5)}


def sample_cpu_s(config: Config, env: int) -> float:
    """CPU seconds to open environment ``env`` and render and photograph all its cameras."""
    start = time.process_time()
    view = EnvironmentView.open(config, 0, env)
    with view.renderer:
        for index in range(config.cameras.total):
            view.render(index)
    return time.process_time() - start


def interleaved_cost(envs: int) -> dict:
    on = load_config("demo")
    off = dataclasses.replace(on, environment=dataclasses.replace(
        on.environment, **{r: 0.0 for r in RULES}))
    seconds = {"off": [], "on": []}
    for env in range(envs):
        for label, config in ((("off", off), ("on", on)) if env % 2 == 0
                              else (("on", on), ("off", off))):
            seconds[label].append(round(sample_cpu_s(config, env), 2))
    return {"environments": envs, "cpu_s": seconds,
            "cpu_on_over_off": round(sum(seconds["on"]) / sum(seconds["off"]), 3)}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=10)
    parser.add_argument("--cost", type=int, default=0, metavar="ENVS",
                        help="only the interleaved CPU-time cost over ENVS environments "
                             "(results in others_cost.json)")
    args = parser.parse_args()
    if args.cost:
        write_results("others_cost", interleaved_cost(args.cost))
        return
    demo = load_config("demo").environment
    results: dict = {"environments": args.envs,
                     "rules": {name: getattr(demo, name) for name in RULES}}
    dataset = (f"[dataset]\nn_environments = {args.envs}\nn_test_environments = 0\n"
               "n_plates = 0\nn_test_plates = 0\n")
    with tempfile.TemporaryDirectory() as tmp:
        for label, rules in (("off", "\n".join(f"{r} = 0.0" for r in RULES)), ("on", "")):
            config = Path(tmp) / f"{label}.toml"
            config.write_text(dataset + "[environment]\n" + rules + "\n")
            report = generate(Path(tmp) / label, config)
            views = args.envs * load_config("demo").cameras.total
            results[label] = {"wall_s": report["wall_s"], "raw_views": views,
                              "wall_s_per_raw_view": round(report["wall_s"] / views, 3),
                              "kept": report["kept"],
                              "seconds_by_phase": report["worker_seconds_by_phase"],
                              **class_8(Path(tmp) / label)}
    results["cost_on_over_off"] = round(results["on"]["wall_s"] / results["off"]["wall_s"], 3)
    write_results("others", results)


if __name__ == "__main__":
    main()
