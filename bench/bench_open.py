"""Opening an environment: wall time by phase, peak RSS, and digests of rendered outputs.

Each process opens three environments with one renderer, as a generation worker does
(environments e, e + 1, e + 2 modulo --envs), after one warm-up process that fills the texture
and damage-bank caches on disk. The first opening is a fresh process's (its peak RSS is its
own); the second and third show a worker's steady state (peak RSS over the process so far).
The phases are building the environment, dressing it (bank reads and damage maps), and
uploading (textures, mipmaps, geometry, sky visibility).
The digests (sha256 of every pass of a few cameras) show whether a change to the open path
changed a byte of output: compare them between two results files.

    .venv/bin/python bench/bench_open.py [--preset paper] [--envs 2] [--cameras 4]
                                         [--label after]
"""

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, write_results  # noqa: E402

CHILD = """
import hashlib, json, resource, sys, time
from glsynth.core.config import load_config
import glsynth.render.view as view_module
from glsynth.render.gl.renderer import Renderer

preset, cameras, envs = sys.argv[1], int(sys.argv[2]), [int(e) for e in sys.argv[3:]]
config = load_config(preset)

def timed(name, fn):
    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            phases[name] = phases.get(name, 0.0) + time.perf_counter() - t
    return wrapper

view_module.build_environment = timed("build_environment", view_module.build_environment)
view_module.dress = timed("dress", view_module.dress)
Renderer.load = timed("upload", Renderer.load)
renderer = Renderer(config.render)
opens = []
for env in envs:
    phases = {}
    t0 = time.perf_counter()
    view = view_module.EnvironmentView.open(config, 0, env, renderer)
    opened = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    digests = {}
    step = max(1, config.cameras.total // max(1, cameras))
    for index in range(0, config.cameras.total, step)[:cameras]:
        _, out = view.render(index)
        digests[str(index)] = {k: hashlib.sha256(getattr(out, k).tobytes()).hexdigest()[:16]
                               for k in ("color", "component", "damage", "depth")}
    opens.append({"environment": env, "open_s": opened, "phases_s": phases,
                  "peak_rss_mib": peak,
                  "damage_textures": sum(1 for a in view.dressing.assignments.values()
                                         if a.damage and a.damage.get("built")),
                  "digests": digests})
    del view
print(json.dumps(opens))
"""


def child(preset: str, cameras: int, envs: list[int]) -> list[dict]:
    out = subprocess.run([sys.executable, "-c", CHILD, preset, str(cameras), *map(str, envs)],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def medians(runs: list[dict]) -> dict:
    return {"open_s_median": statistics.median(r["open_s"] for r in runs),
            "peak_rss_mib_median": statistics.median(r["peak_rss_mib"] for r in runs),
            "phases_s_median": {k: statistics.median(r["phases_s"][k] for r in runs)
                                for k in runs[0]["phases_s"]}}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--envs", type=int, default=2, help="at least 2")
    parser.add_argument("--cameras", type=int, default=4, help="cameras rendered for digests")
    parser.add_argument("--label", default="after", help="results: bench/results/open/LABEL")
    args = parser.parse_args()
    if args.envs < 2:
        parser.error(f"--envs {args.envs}: give at least 2 (each process opens three in turn)")
    child(args.preset, 0, [0])  # fills the caches
    runs = [child(args.preset, args.cameras,
                  [env, (env + 1) % args.envs, (env + 2) % args.envs])
            for env in range(args.envs)]
    nth = {name: sorted((run[k] for run in runs), key=lambda r: r["environment"])
           for k, name in enumerate(("first", "second", "third"))}
    digests: dict[int, list[dict]] = {}
    for run in runs:
        for r in run:
            digests.setdefault(r["environment"], []).append(r["digests"])
    (RESULTS / "open").mkdir(parents=True, exist_ok=True)
    write_results(f"open/{args.label}", {
        "preset": args.preset,
        **{f"{name}_open": medians(records) for name, records in nth.items()},
        **{f"{name}_by_environment": records for name, records in nth.items()},
        "digests_agree_between_openings": all(
            all(d == ds[0] for d in ds) for ds in digests.values())})


if __name__ == "__main__":
    main()
