"""Does the raster shortcut cost the networks accuracy? Train FCN58 on glsynth (GL) renders and on
Cycles renders of the same views, test each on GL and on Cycles renders of held-out
environments, and measure what photometric augmentation and lighting randomisation win back.

    .venv/bin/python bench/bench_transfer.py [--envs 8] [--test-envs 2] [--cameras 24]
        [--samples 4] [--size 480x270] [--schedule 1e-3:30,1e-4:10] [--seeds 0,1]
        [--out out/bench-transfer] [--stage data|all]

Datasets (paper preset at the balanced quality, regular cameras only, no plates; root seed 0):
- gl: the GL renderer; cycles: the Cycles twin of the same views (`--renderer cycles`), whose
  labels and depth are GL's byte for byte and whose kept views are GL's;
- gl_fixed: the training environments of gl with one sun and sky for all of them (each range
  of [render] at its midpoint) instead of a draw per environment.

Training sets: gl, cycles, gl + `--augment all`, gl_fixed. Test sets: the held-out environments
of gl and of cycles. Component and depth networks, one per training seed. Everything lands in
--out and resumes; generation times are measured on the first complete run of each dataset.
Writes bench/results/transfer.json.
"""

import argparse
import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, training_env, write_results  # noqa: E402

FIXED_LIGHT = ("sun_elevation_deg = [45.0, 45.0]\nsun_azimuth_deg = [180.0, 180.0]\n"
               "sun_irradiance = [3.0, 3.0]\nturbidity = [3.0, 3.0]\n")
TRAIN_SETS = {"gl": ("gl", ()), "cycles": ("cycles", ()), "gl_augment": ("gl", ("all",)),
              "gl_fixed_light": ("gl_fixed", ())}
TASKS = {"component": ("gl", "cycles", "gl_augment", "gl_fixed_light"), "depth": ("gl", "cycles")}


def glsynth(*args: str, env: dict | None = None) -> None:
    subprocess.run([sys.executable, "-m", "glsynth", *args], check=True, env=env)


def dataset_configs(args: argparse.Namespace) -> dict[str, tuple[str, list[str]]]:
    """name -> (TOML overlay of the paper preset, extra generate options)."""
    cameras = f"[cameras]\nn_regular = {args.cameras}\nn_closeup = 0\n"
    plates = "n_plates = 0\nn_test_plates = 0\n"
    full = f"[dataset]\nn_environments = {args.envs}\nn_test_environments = {args.test_envs}\n"
    train_only = f"[dataset]\nn_environments = {args.envs - args.test_envs}\n" \
                 "n_test_environments = 0\n"
    return {"gl": (full + plates + cameras, []),
            "cycles": (full + plates + cameras, ["--renderer", "cycles", "--samples",
                                                 str(args.samples)]),
            "gl_fixed": (train_only + plates + cameras + "[lighting]\n" + FIXED_LIGHT, [])}


def generate(out: Path, args: argparse.Namespace) -> dict:
    """Generate (or resume) each dataset; seconds of the runs that wrote its images."""
    times_file = out / "generation_seconds.json"
    times = json.loads(times_file.read_text()) if times_file.exists() else {}
    for name, (toml, options) in dataset_configs(args).items():
        config = out / f"{name}.toml"
        config.write_text(toml)
        data = out / name
        t0 = time.perf_counter()
        glsynth("generate", "--preset", "paper", "--quality", "balanced", "--config",
                str(config), "--seed", "0", "--out", str(data), "--workers", "1", *options)
        report = json.loads((data / "report.json").read_text())
        if report["images_written_this_run"]:
            times[name] = times.get(name, 0.0) + time.perf_counter() - t0
            times_file.write_text(json.dumps(times, indent=2))
    return times


def colour_gap(a: Path, b: Path, size: tuple[int, int]) -> dict:
    """PSNR and mean absolute difference (8-bit levels) of each view of two datasets at the
    networks' input size: how far the two renderers' colours are apart."""
    from glsynth.model.data import read_rgb, resize_rgb

    psnr, mad = [], []
    for path in sorted((a / "img_syn_raw").rglob("*.png")):
        x, y = (resize_rgb(read_rgb(root / path.relative_to(a)), size).astype(float)
                for root in (a, b))
        psnr.append(10 * math.log10(255.0 ** 2 / max(((x - y) ** 2).mean(), 1e-12)))
        mad.append(float(abs(x - y).mean()))
    return {"views": len(psnr), "psnr_db_median": statistics.median(psnr),
            "psnr_db_range": [min(psnr), max(psnr)],
            "mean_abs_diff_median": statistics.median(mad)}


def same_views_and_labels(a: Path, b: Path) -> dict:
    """Whether two datasets list the same views and hold byte-identical labels and depth."""
    lists = all((a / f).read_bytes() == (b / f).read_bytes()
                for f in ("files_train.csv", "files_test.csv"))
    maps = [p.relative_to(a) for p in (a / "synthetic").rglob("*") if p.is_file()]
    same = sum((a / m).read_bytes() == (b / m).read_bytes() for m in maps)
    images = [p.relative_to(a) for p in (a / "img_syn_raw").rglob("*.png")]
    differ = sum((a / m).read_bytes() != (b / m).read_bytes() for m in images)
    return {"manifests_equal": lists, "label_and_depth_maps": len(maps),
            "identical_maps": same, "images": len(images), "images_that_differ": differ}


def train_and_test(out: Path, args: argparse.Namespace) -> list[dict]:
    """Every (task, training set, seed) run, evaluated on both test sets; resumes."""
    cells = []
    for task, sets in TASKS.items():
        for name in sets:
            data, augment = TRAIN_SETS[name]
            for seed in args.seeds.split(","):
                run = out / "runs" / f"{task}_{name}_seed{seed}"
                if not (run / "model.pt").exists():
                    glsynth("train", "--task", task, "--data", str(out / data), "--out", str(run),
                            "--image-size", args.size, "--schedule", args.schedule,
                            "--seed", seed, "--val-count", "0", "--cache-inputs",
                            "--augment", ",".join(augment) or "none", env=training_env())
                history = json.loads((run / "history.json").read_text())
                cell = {"task": task, "train": name, "seed": int(seed),
                        "epochs": history[-1]["epoch"],
                        "train_seconds": history[-1]["train_seconds_total"]}
                for test in ("gl", "cycles"):
                    result = run / f"test_{test}"
                    if not (result / "metrics.json").exists():
                        glsynth("evaluate", "--run", str(run), "--data", str(out / test),
                                "--out", str(result), "--examples", "4")
                    cell[f"test_{test}"] = scores(json.loads(
                        (result / "metrics.json").read_text()))
                cells.append(cell)
    return cells


def scores(metrics: dict) -> dict:
    if metrics["task"] == "depth":
        return {"images": metrics["images"], **metrics["depth"]}
    return {"images": metrics["images"], "miou": metrics["mean"]["iou"],
            "iou": {k: v["iou"] for k, v in metrics["per_class"].items()}}


def table(cells: list[dict]) -> dict:
    """Per task, training set and test set: the mean and spread over seeds of each metric."""
    keys = {"component": ("miou",), "depth": ("mae_m", "rmse_m", "ard")}
    out: dict = {}
    for cell in cells:
        for test in ("gl", "cycles"):
            row = out.setdefault(cell["task"], {}).setdefault(cell["train"], {}).setdefault(
                f"test_{test}", {k: [] for k in keys[cell["task"]]})
            for k in keys[cell["task"]]:
                row[k].append(cell[f"test_{test}"][k])
    for task in out.values():
        for train in task.values():
            for test in train.values():
                for k, values in test.items():
                    test[k] = {"mean": sum(values) / len(values), "min": min(values),
                               "max": max(values), "values": values}
    return out


def answers(cells: list[dict], times: dict, args: argparse.Namespace) -> dict:
    """The issue's two questions in mIoU points on the Cycles test set, per seed (cells of one
    seed paired): the loss of training on GL instead of Cycles, and what augmentation and
    per-environment lighting win back; and what each training set cost to render."""
    miou = {(c["train"], c["seed"]): 100 * c["test_cycles"]["miou"] for c in cells
            if c["task"] == "component"}
    seeds = sorted({s for _, s in miou})

    def points(a: str, b: str) -> dict:
        values = [round(miou[a, s] - miou[b, s], 2) for s in seeds]
        return {"mean": round(sum(values) / len(values), 2), "per_seed": values}

    train_share = (args.envs - args.test_envs) / args.envs
    return {
        "miou_points_lost_training_on_gl": points("cycles", "gl"),
        "won_back_by_augmentation": points("gl_augment", "gl"),
        "won_back_by_lighting_randomisation": points("gl", "gl_fixed_light"),
        "training_set_render_seconds": {
            "gl_measured_alone (gl_fixed: the training environments only)": times.get(
                "gl_fixed"),
            "gl_pro_rata": times["gl"] * train_share, "cycles_pro_rata": times["cycles"]
            * train_share},
        "gl_to_cycles_time_ratio": times["gl"] / times["cycles"]}


def markdown(tab: dict) -> str:
    """The README's tables: mean (min-max over seeds) per training set and test set."""
    def cell(v: dict, scale: float, digits: int) -> str:
        return f"{v['mean'] * scale:.{digits}f} ({v['min'] * scale:.{digits}f}-" \
               f"{v['max'] * scale:.{digits}f})"

    lines = ["| component mIoU % | GL test | Cycles test |", "|---|---|---|"]
    for train, row in tab["component"].items():
        lines.append(f"| trained on {train} | {cell(row['test_gl']['miou'], 100, 1)} | "
                     f"{cell(row['test_cycles']['miou'], 100, 1)} |")
    lines += ["", "| depth MAE m / RMSE m / ARD % | GL test | Cycles test |", "|---|---|---|"]
    for train, row in tab["depth"].items():
        parts = [" / ".join((cell(row[t]["mae_m"], 1, 2), cell(row[t]["rmse_m"], 1, 2),
                             cell(row[t]["ard"], 100, 1))) for t in ("test_gl", "test_cycles")]
        lines.append(f"| trained on {train} | {parts[0]} | {parts[1]} |")
    return "\n".join(lines) + "\n"


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--test-envs", type=int, default=2)
    parser.add_argument("--cameras", type=int, default=24)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--schedule", default="1e-3:30,1e-4:10")
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--out", default="out/bench-transfer")
    parser.add_argument("--stage", choices=("data", "all"), default="all")
    return parser.parse_args()


def main() -> None:
    args = parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    times = generate(out, args)
    if args.stage == "data":
        print(json.dumps(times, indent=2))
        return
    check = same_views_and_labels(out / "gl", out / "cycles")
    if not (check["manifests_equal"] and check["identical_maps"] == check["label_and_depth_maps"]):
        raise SystemExit(f"gl and cycles datasets differ in views or labels: {check}")
    cells = train_and_test(out, args)
    kept = {name: json.loads((out / name / "report.json").read_text())["kept"]
            for name in dataset_configs(args)}
    tab = table(cells)
    (RESULTS / "transfer.md").write_text(markdown(tab))
    write_results("transfer", {
        "scale": {"environments": args.envs, "test_environments": args.test_envs,
                  "regular_cameras_per_environment": args.cameras, "kept_views": kept,
                  "cycles_samples_at_1920x1080": args.samples, "input_size": args.size,
                  "schedule": args.schedule, "seeds": args.seeds},
        "gl_against_cycles": {**check, **colour_gap(
            out / "gl", out / "cycles", tuple(int(v) for v in args.size.split("x")))},
        "generation_seconds": times, "answers": answers(cells, times, args),
        "table": tab,
        "cells": cells})


if __name__ == "__main__":
    main()
