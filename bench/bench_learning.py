"""A reduced-scale learning result: generate a small dataset, train FCN58 for each task for a
fixed CPU budget, and evaluate on the held-out environments, next to the paper's figures.

    .venv/bin/python bench/bench_learning.py [--envs 8] [--budget-min 6] [--size 480x270]

The dataset (demo preset, more environments and cameras) and the runs go to
out/bench-learning/; both resume if the command is started again.
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

PAPER = {"component_miou": 0.879, "concrete_iou": 0.534, "rebar_iou": 0.506,
         "depth_mae_m": 1.20, "depth_rmse_m": 1.85, "depth_ard": 0.1002}


def glsynth(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "glsynth", *args], check=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--budget-min", type=float, default=6.0)
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--out", default="out/bench-learning")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    config = out / "learning.toml"
    config.write_text(f"[dataset]\nn_environments = {args.envs}\nn_test_environments = 2\n"
                      "n_plates = 48\nn_test_plates = 8\nplates_per_task = 12\n"
                      "[cameras]\nn_regular = 12\nn_closeup = 12\n")
    data = out / "dataset"
    glsynth("generate", "--preset", "demo", "--config", str(config), "--seed", "7",
            "--out", str(data), "--workers", "2")
    results = {"dataset": json.loads((data / "report.json").read_text())["kept"],
               "budget_min_per_task": args.budget_min, "image_size": args.size}
    for task in ("component", "damage", "depth"):
        run = out / f"run_{task}_{args.size}"
        glsynth("train", "--task", task, "--data", str(data), "--out", str(run),
                "--image-size", args.size, "--schedule", "1e-3:10000",
                "--time-budget-min", str(args.budget_min))
        glsynth("evaluate", "--run", str(run), "--data", str(data))
        metrics = json.loads((run / "eval_test" / "metrics.json").read_text())
        history = json.loads((run / "history.json").read_text())
        entry = {"epochs": history[-1]["epoch"], "test_images": metrics["images"],
                 "train_images_per_s": history[-1]["images_per_s"]}
        if task == "depth":
            entry.update(metrics["depth"])
        else:
            entry["mean_iou"] = metrics["mean"]["iou"]
            entry["iou"] = {k: v["iou"] for k, v in metrics["per_class"].items()}
        results[task] = entry
    results["paper"] = PAPER
    write_results("learning", results)


if __name__ == "__main__":
    main()
