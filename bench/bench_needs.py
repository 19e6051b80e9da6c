"""What modelling only what a scene requires saves: opening an environment with culling
(parts no camera of the environment sees are not uploaded; their columns get no damage
texture) against uploading everything with every column damaged, and drawing only the passes
asked for against all of them, for environments with 100 cameras (the paper's) and with few.
Each opening runs in a fresh process, so the peak RSS is its own.

    .venv/bin/python bench/bench_needs.py [--preset paper] [--envs 2] [--cameras 100,6]
"""

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

CHILD = """
import dataclasses, json, resource, sys, time
from glsynth.core.config import load_config
from glsynth.render.view import EnvironmentView
import glsynth.render.view as render

preset, env, mode, n = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
config = load_config(preset)
config = dataclasses.replace(config, cameras=dataclasses.replace(
    config.cameras, n_regular=n - n // 2, n_closeup=n // 2))
if mode == "everything":
    # Every part uploaded and every damaged column textured, as without visibility tests.
    render.visible_parts = lambda parts, cameras: {p.name for p in parts}
t0 = time.perf_counter()
view = EnvironmentView.open(config, 0, env, cull=(mode == "culled"))
opened = time.perf_counter() - t0
passes = {}
for name, wanted in (("all", {"color", "component", "damage", "depth"}),
                     ("color", {"color"}), ("labels_depth", {"component", "damage", "depth"})):
    times = []
    for index in range(0, n, max(1, n // 10)):
        t = time.perf_counter()
        view.render(index, frozenset(wanted))
        times.append(time.perf_counter() - t)
    passes[name] = sorted(times)[len(times) // 2]
print(json.dumps({"open_s": opened, "parts_uploaded": len(view.scene.parts),
                  "parts": len(view.environment.parts),
                  "damage_textures": sum(1 for a in view.dressing.assignments.values()
                                         if a.damage and a.damage.get("built")),
                  "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "render_median_s": passes}))
"""


def child(preset: str, env: int, mode: str, cameras: int) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, preset, str(env), mode, str(cameras)],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def measure(preset: str, envs: int, cameras: int) -> dict:
    runs = {mode: [child(preset, e, mode, cameras) for e in range(envs)]
            for mode in ("culled", "everything")}
    results: dict = {"cameras_per_environment": cameras}
    for mode, items in runs.items():
        results[mode] = {
            "open_s_median": statistics.median(r["open_s"] for r in items),
            "peak_rss_mib_median": statistics.median(r["peak_rss_mib"] for r in items),
            "parts_uploaded": [r["parts_uploaded"] for r in items],
            "parts": [r["parts"] for r in items],
            "damage_textures": [r["damage_textures"] for r in items],
            "render_median_s": {k: statistics.median(r["render_median_s"][k] for r in items)
                                for k in items[0]["render_median_s"]}}
    c, e = results["culled"], results["everything"]
    results["saving"] = {
        "open_time_ratio_everything_over_culled": round(e["open_s_median"] / c["open_s_median"],
                                                        2),
        "peak_rss_saved_mib": round(e["peak_rss_mib_median"] - c["peak_rss_mib_median"]),
        "all_passes_render_ratio_everything_over_culled": round(
            e["render_median_s"]["all"] / c["render_median_s"]["all"], 2),
        "colour_only_over_all_passes": round(c["render_median_s"]["color"] /
                                             c["render_median_s"]["all"], 2),
        "labels_depth_only_over_all_passes": round(c["render_median_s"]["labels_depth"] /
                                                   c["render_median_s"]["all"], 2)}
    return results


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--cameras", default="100,6",
                        help="cameras per environment, comma-separated (half regular)")
    args = parser.parse_args()
    counts = [int(c) for c in args.cameras.split(",")]
    child(args.preset, 0, "culled", counts[0])  # warm the texture and damage-bank caches
    child(args.preset, 0, "everything", counts[0])
    write_results("needs", {"preset": args.preset, "environments": args.envs,
                            "by_cameras": [measure(args.preset, args.envs, n) for n in counts]})


if __name__ == "__main__":
    main()
