"""End-to-end generation throughput: images per hour for 1, 2 and 3 workers, where the time
goes, each worker's peak RSS, the CPU seconds an image costs (user + system of the generate
process and its workers: steadier than the wall clock on a shared machine), and the projection
for the paper's dataset (20,000 raw views + 3,000 plates).

    .venv/bin/python bench/bench_generate.py [--envs 3] [--plates 20] [--quality balanced]
                                             [--cold] [--workers 1,2,3]

Uses the paper preset (100 cameras per environment, 1920x1080, 2048 px damage textures) on a
few environments, each run in a fresh output folder with warm texture caches (--cold adds a
first run that makes them); with --quality, that preset's knobs instead (results in
generate_<quality>.json).
"""

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

PAPER_VIEWS, PAPER_PLATES = 20_000, 3_000


def cpu_seconds_of_children() -> float:
    """User + system seconds of every finished child process so far, and of theirs."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(out: Path, config: Path, workers: int, quality: str | None) -> tuple[dict, float]:
    """The run's report and the CPU seconds it took."""
    before = cpu_seconds_of_children()
    done = subprocess.run([sys.executable, "-m", "glsynth", "generate", "--preset", "paper",
                           "--config", str(config), "--seed", "0", "--out", str(out),
                           "--workers", str(workers),
                           *(["--quality", quality] if quality else [])],
                          stderr=subprocess.PIPE, text=True)
    if done.returncode:  # the progress bar is dropped; a failure's own lines are not
        sys.exit(f"glsynth generate failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads((out / "report.json").read_text()), cpu_seconds_of_children() - before


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=3)
    parser.add_argument("--plates", type=int, default=20)
    parser.add_argument("--quality", default=None, help="a glsynth quality preset")
    parser.add_argument("--cold", action="store_true",
                        help="first a run that makes the texture and damage-bank caches")
    parser.add_argument("--workers", default="1,2,3",
                        help="the worker counts to run, one run each")
    args = parser.parse_args()
    runs = [(f"{n} worker{'s' if n > 1 else ''}", n)
            for n in (int(w) for w in args.workers.split(","))]
    if args.cold:
        runs.insert(0, ("cold caches, 1 worker", 1))
    results: dict = {"quality": args.quality or "paper preset (high)"}
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "bench.toml"
        config.write_text(f"[dataset]\nn_environments = {args.envs}\nn_test_environments = 0\n"
                          f"n_plates = {args.plates}\nn_test_plates = 0\n"
                          f"plates_per_task = {max(1, args.plates // 2)}\n")
        for label, workers in runs:
            report, cpu = run(Path(tmp) / label.replace(" ", "_").replace(",", ""), config,
                              workers, args.quality)
            views = args.envs * 100
            wall = report["wall_s"]
            per_view = wall / (views + args.plates)
            results[label] = {
                "raw views": views, "plates": args.plates, "kept": report["kept"],
                "wall_s": wall, "images_per_hour": round(3600 * (views + args.plates) / wall),
                "cpu_s": round(cpu, 1), "cpu_s_per_image": round(cpu / (views + args.plates), 3),
                "worker_seconds_by_phase": report["worker_seconds_by_phase"],
                "worker_peak_rss_mib": report["worker_peak_rss_mib"],
                "projected_hours_paper_dataset": round(
                    per_view * (PAPER_VIEWS + PAPER_PLATES) / 3600, 2),
                "projected_cpu_hours_paper_dataset": round(
                    cpu / (views + args.plates) * (PAPER_VIEWS + PAPER_PLATES) / 3600, 2)}
    write_results(f"generate_{args.quality}" if args.quality else "generate", results)


if __name__ == "__main__":
    main()
