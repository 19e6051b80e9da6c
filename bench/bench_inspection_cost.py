"""An inspection-preset sample's cost at a baseline checkout and at this one, side by side.

    .venv/bin/python bench/bench_inspection_cost.py --baseline CHECKOUT [--seed 11] [--env 0]
                                                   [--cameras 6] [--rounds 3]
                                                   [--without-issue-40] [--face-crack-px PX]

CHECKOUT is another checkout of glsynth with its own .venv (issue 39's baseline: b2f8da0).
Each round runs one fresh process per checkout, in turn, the order swapped every round so that
a busy machine slows both alike. A process runs in its checkout's folder with its checkout's
.venv/bin/python, so it imports its own glsynth and its own inspection preset, and does what
that checkout's `glsynth render --preset inspection --seed S --env E --camera 0 1 ... N-1`
does: opens the environment (culled for those cameras where the checkout culls so), renders
camera N once to compile the shaders, then for each camera 0..N-1 renders, reads back,
photographs (where the checkout has a camera model) and writes the view's files
(glsynth.render.view.write_render). Only that last part is timed, per view, in wall seconds
and in process CPU seconds (every thread, llvmpipe's included): on a machine shared with other
jobs CPU seconds are the steadier figure. The CPU seconds are also split: render and read-back,
camera model, files. A round's figure is its views' mean; the report
gives each checkout's median over rounds and the ratio this / baseline. --without-issue-40
adds a third process a round: this checkout with issue 40's parts of the inspection preset off
(the environment section as the paper preset's: no town, solid fences, no class 8; no severe
damage as geometry), which b2f8da0 predates. --face-crack-px sets this checkout's [cameras]
face_crack_px (b2f8da0's preset: 3), so that both place their crack-aimed cameras alike. Writes
bench/results/inspection_cost.json (with --face-crack-px: inspection_cost_face_crack_px_PX.json).
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

HERE = Path(__file__).resolve().parents[1]
CHILD = """
import inspect, json, sys, time
from dataclasses import replace
from pathlib import Path
import glsynth
from glsynth.core.config import load_config
from glsynth.render.view import EnvironmentView, write_render

args = json.loads(sys.argv[1])
cameras, warm_up, out = args["cameras"], max(args["cameras"]) + 1, Path(args["out"])
kwargs = {}
if "rendering" in inspect.signature(EnvironmentView.open).parameters:
    kwargs["rendering"] = cameras + [warm_up]  # as `glsynth render --camera` culls
config = load_config("inspection")
if args["without_issue_40"]:
    config = replace(config, environment=load_config("paper").environment,
                     damage=replace(config.damage, geometry=False))
if args["face_crack_px"] is not None:
    config = replace(config, cameras=replace(config.cameras, face_crack_px=args["face_crack_px"]))
view = EnvironmentView.open(config, args["seed"], args["env"], **kwargs)
meta = {"root_seed": args["seed"], "env": args["env"], "renderer": "gl"}

def sample(index):
    # CPU s in render and read-back, camera model, files (view.render's work, in two calls).
    c0 = time.process_time()
    if hasattr(view, "photograph"):
        placement, output = view.render(index, photo=False)
        c1 = time.process_time()
        output = view.photograph(output, placement.camera, index)
    else:
        placement, output = view.render(index)
        c1 = time.process_time()
    c2 = time.process_time()
    write_render(out / f"camera_{index:03d}", placement, output, meta)
    return c1 - c0, c2 - c1, time.process_time() - c2

sample(warm_up)
wall, cpu, stages = [], [], []
for index in cameras:
    w0, c0 = time.perf_counter(), time.process_time()
    stages.append(sample(index))
    wall.append(time.perf_counter() - w0)
    cpu.append(time.process_time() - c0)
print(json.dumps({"glsynth": glsynth.__file__, "wall_s": wall, "cpu_s": cpu,
                  "render_cpu_s": [s[0] for s in stages],
                  "camera_cpu_s": [s[1] for s in stages],
                  "files_cpu_s": [s[2] for s in stages]}))
"""


def run_checkout(checkout: Path, seed: int, env: int, cameras: list[int],
                 without_issue_40: bool = False, face_crack_px: float | None = None) -> dict:
    """One fresh process of ``checkout``'s python in its folder: per-view wall and CPU s."""
    with tempfile.TemporaryDirectory(prefix="inspection_cost_") as out:
        args = {"seed": seed, "env": env, "cameras": cameras, "out": out,
                "without_issue_40": without_issue_40, "face_crack_px": face_crack_px}
        done = subprocess.run([str(checkout / ".venv" / "bin" / "python"), "-c", CHILD,
                               json.dumps(args)], cwd=checkout, capture_output=True,
                              text=True, check=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if not Path(result["glsynth"]).resolve().is_relative_to(checkout.resolve()):
        raise RuntimeError(f"{checkout}'s python imported glsynth from {result['glsynth']}")
    return result


def measure(baseline: Path, seed: int, env: int, n_cameras: int, rounds: int,
            without_issue_40: bool, face_crack_px: float | None = None) -> dict:
    cameras = list(range(n_cameras))
    checkouts = {"baseline": (baseline, False), "this": (HERE, False)}
    if without_issue_40:
        checkouts["this_without_issue_40"] = (HERE, True)
    keys = ("wall_s", "cpu_s", "render_cpu_s", "camera_cpu_s", "files_cpu_s")
    per_round: dict[str, dict[str, list[float]]] = {
        name: {key: [] for key in keys} for name in checkouts}
    for r in range(rounds):
        order = list(checkouts) if r % 2 == 0 else list(checkouts)[::-1]
        for name in order:
            # The baseline keeps its own preset's aims; only this checkout's are overridden.
            result = run_checkout(checkouts[name][0], seed, env, cameras, checkouts[name][1],
                                  None if name == "baseline" else face_crack_px)
            for key in keys:
                per_round[name][key].append(statistics.mean(result[key]))
            print(f"round {r}: {name} {statistics.mean(result['wall_s']):.2f} s wall, "
                  f"{statistics.mean(result['cpu_s']):.2f} s CPU a view", file=sys.stderr)
    medians = {name: {key: statistics.median(values) for key, values in times.items()}
               for name, times in per_round.items()}
    ratio = {name: {key: medians[name][key] / medians["baseline"][key]
                    for key in ("wall_s", "cpu_s")} for name in checkouts if name != "baseline"}
    return {"baseline": str(baseline), "this": str(HERE), "seed": seed, "env": env,
            "cameras": cameras, "rounds": rounds, "face_crack_px": face_crack_px,
            "per_view_mean_each_round": per_round, "median_per_view": medians,
            "ratio_over_baseline": ratio}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--baseline", type=Path, required=True,
                   help="the other checkout (with its own .venv)")
    p.add_argument("--seed", type=int, default=11)
    p.add_argument("--env", type=int, default=0)
    p.add_argument("--cameras", type=int, default=6)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--without-issue-40", action="store_true",
                   help="also time this checkout with issue 40's parts of the preset off")
    p.add_argument("--face-crack-px", type=float, default=None,
                   help="this checkout's [cameras] face_crack_px (b2f8da0's preset has 3): "
                        "the same camera placement at both, to tell placement from code")
    args = p.parse_args()
    # An override's run is kept beside the preset's, not over it.
    name = ("inspection_cost" if args.face_crack_px is None
            else f"inspection_cost_face_crack_px_{args.face_crack_px:g}")
    write_results(name, measure(args.baseline, args.seed, args.env, args.cameras, args.rounds,
                                args.without_issue_40, args.face_crack_px))


if __name__ == "__main__":
    main()
