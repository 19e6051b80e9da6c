"""End-to-end generation throughput: images per hour for 1 and 2 workers, where the time goes,
and the projection for the paper's dataset (20,000 raw views + 3,000 plates).

    .venv/bin/python bench/bench_generate.py [--envs 2] [--plates 20] [--quality balanced]

Uses the paper preset (100 cameras per environment, 1920x1080, 2048 px damage textures) on a
few environments, each run in a fresh output folder with warm texture caches; with --quality,
that preset's knobs instead (results in generate_<quality>.json).
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

PAPER_VIEWS, PAPER_PLATES = 20_000, 3_000


def run(out: Path, config: Path, workers: int, quality: str | None) -> dict:
    subprocess.run([sys.executable, "-m", "glsynth.cli", "generate", "--preset", "paper",
                    "--config", str(config), "--seed", "0", "--out", str(out),
                    "--workers", str(workers), *(["--quality", quality] if quality else [])],
                   check=True, stderr=subprocess.DEVNULL)
    return json.loads((out / "report.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--plates", type=int, default=20)
    parser.add_argument("--quality", default=None, help="a glsynth quality preset")
    args = parser.parse_args()
    results: dict = {"quality": args.quality or "paper preset (high)"}
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "bench.toml"
        config.write_text(f"[dataset]\nn_environments = {args.envs}\nn_test_environments = 0\n"
                          f"n_plates = {args.plates}\nn_test_plates = 0\n"
                          f"plates_per_task = {max(1, args.plates // 2)}\n")
        for label, workers in (("cold caches, 1 worker", 1), ("1 worker", 1),
                               ("2 workers", 2)):
            # The first run also makes the texture repository and damage-bank entries.
            report = run(Path(tmp) / label.replace(" ", "_").replace(",", ""), config, workers,
                         args.quality)
            views = args.envs * 100
            wall = report["wall_s"]
            per_view = wall / (views + args.plates)
            results[label] = {
                "raw views": views, "plates": args.plates, "kept": report["kept"],
                "wall_s": wall, "images_per_hour": round(3600 * (views + args.plates) / wall),
                "worker_seconds_by_phase": report["worker_seconds_by_phase"],
                "projected_hours_paper_dataset": round(
                    per_view * (PAPER_VIEWS + PAPER_PLATES) / 3600, 2)}
    write_results(f"generate_{args.quality}" if args.quality else "generate", results)


if __name__ == "__main__":
    main()
