"""Many sim-to-real networks at once: the medians and spreads of glsynth bench sim2real's
networks over many repeats, trained in parallel processes (one network each) on a GPU.

    python bench/bench_sim2real_many.py --real TEST --synthetic DS... [--other-real FOLDER...]
        [--plan 300:8,1500:4] [--workers 12] [--device cuda] [--name sim2real_many]

Each network is the one `glsynth bench sim2real --test-share 1 --steps S` trains as its
repeat r (the same function, sim2real.scored_run, from repeat_item(r)'s draws), so a run of
``--plan 300:8`` holds the networks of `--repeats 8`; the processes only run them side by
side. TEST is tested whole (--test-share 1), as in the runs of
docs/results.md, and the same-kind network comes from an --other-real training split. One
network of 300 steps takes a minute or more on two CPU cores; on an H200 machine (16 cores),
twelve at a time took about 20 s each. Prints each network as it ends and rewrites
bench/results/<name>.json (every network's scores, and each training set's median, mean and
spread per step count; "complete" once all are in).
"""

import argparse
import multiprocessing
import os
import statistics
import sys
import time
from pathlib import Path

from common import write_results

_DATA: dict = {}
"""A worker's training and test sets by name, read once when it starts."""


def read_sets(args: argparse.Namespace) -> dict[str, list]:
    """Every training set by its network's name (sim2real.network_names: folder names,
    refused where two are alike or an other real folder is the test folder) and the test
    folder as "real", read in the parent: a bad folder is one line before any worker starts
    (a pool would restart a failing worker forever)."""
    from glsynth.model.sim2real import REAL, network_names

    from glsynth.data.crack_folders import read_real_folder, read_synthetic

    names = network_names(args.synthetic, args.other_real, args.real)
    readers = [read_synthetic] * len(args.synthetic) + [read_real_folder] * len(args.other_real)
    data = {REAL: read_real_folder(args.real)}
    for name, path, read in zip(names, [*args.synthetic, *args.other_real], readers,
                                strict=True):
        data[name] = read(path)
    return data


def parse_plan(plan: str) -> list[tuple[int, int]]:
    """--plan "300:8,1500:4": (steps, repeats) pairs, each at least 1."""
    from glsynth.core.errors import UserError

    try:
        pairs = [tuple(int(v) for v in item.split(":", 1)) for item in plan.split(",")]
    except ValueError:
        pairs = []
    if not pairs or any(len(pair) != 2 or min(pair) < 1 for pair in pairs):
        raise UserError(f"--plan {plan!r}: give steps:repeats pairs of positive integers, "
                        "comma-separated (e.g. 300:8,1500:4)")
    return pairs


def _start_worker(data: dict[str, list]) -> None:
    import torch

    torch.set_num_threads(1)  # the workers share the cores; each network is small
    _DATA.update(data)


def _network(task: tuple[str, str, int, int, str]) -> dict:
    """One network trained on a set for ``steps`` from repeat ``repeat``'s draws, scored on
    the test folder: sim2real.scored_run, as `glsynth bench sim2real` runs each repeat."""
    import torch
    from glsynth.model import sim2real

    test, train, steps, repeat, device_name = task
    settings = sim2real.Sim2RealSettings(steps=steps, test_share=1.0, device=device_name)
    t0 = time.perf_counter()
    run = sim2real.scored_run(_DATA[train], _DATA[test], settings, sim2real.repeat_item(repeat),
                              torch.device(device_name))
    return {"trained_on": train, "steps": steps, "repeat": repeat,
            "seconds": time.perf_counter() - t0, **run.score, **run.training}


def summarise(networks: list[dict]) -> dict:
    """Each (steps, training set): how many networks, the median, mean, sample standard
    deviation and range of F1."""
    out: dict = {}
    for steps in sorted({n["steps"] for n in networks}):
        for name in dict.fromkeys(n["trained_on"] for n in networks):
            f1 = [n["f1"] for n in networks if n["steps"] == steps and n["trained_on"] == name]
            if f1:
                out.setdefault(str(steps), {})[name] = {
                    "networks": len(f1), "median": statistics.median(f1),
                    "mean": statistics.fmean(f1),
                    "sd": statistics.stdev(f1) if len(f1) > 1 else 0.0,
                    "range": [min(f1), max(f1)]}
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--real", required=True, help="real test folder (images/, masks/), whole")
    p.add_argument("--synthetic", nargs="+", required=True, help="glsynth datasets")
    p.add_argument("--other-real", nargs="*", default=[], help="real training folders")
    p.add_argument("--plan", default="300:8", help="steps:repeats, comma-separated")
    p.add_argument("--workers", type=int, default=12)
    p.add_argument("--device", default="cuda")
    p.add_argument("--name", default="sim2real_many", help="results file name")
    args = p.parse_args()
    from glsynth.model.runtime import pick_device
    from glsynth.model.sim2real import REAL

    from glsynth.core.errors import UserError

    try:
        if args.workers < 1:
            raise UserError(f"--workers {args.workers}: give 1 or more")
        plan = parse_plan(args.plan)
        device = str(pick_device(args.device))  # an absent device: one line, before any read
        data = read_sets(args)
    except UserError as err:
        sys.exit(f"bench_sim2real_many: {err}")
    tasks = [(REAL, name, steps, repeat, device) for steps, repeats in plan
             for repeat in range(repeats) for name in data if name != REAL]
    tasks.sort(key=lambda task: -task[2])  # the long networks first: the workers end together
    result = {"test": Path(args.real).name, "device": device, "plan": args.plan,
              "workers": args.workers, "cpu_count": os.cpu_count(), "complete": False,
              "networks": []}
    t0 = time.perf_counter()
    context = multiprocessing.get_context("spawn")  # CUDA cannot be forked into workers
    # Each worker gets its own copy of the sets (pickled once to each): a few hundred MB.
    with context.Pool(min(args.workers, len(tasks)), _start_worker, (data,)) as pool:
        for network in pool.imap_unordered(_network, tasks):
            result["networks"].append(network)
            print(f"{time.perf_counter() - t0:6.0f} s  {network['trained_on']:20s} "
                  f"steps {network['steps']:5d}  repeat {network['repeat']:2d}  "
                  f"F1 {network['f1']:.3f}", flush=True)
            # Kept as each network ends: a failure later loses none of those finished.
            result.update(wall_s=time.perf_counter() - t0,
                          summary=summarise(result["networks"]))
            write_results(args.name, result, quiet=True)
    result["complete"] = True
    write_results(args.name, result)


if __name__ == "__main__":
    main()
