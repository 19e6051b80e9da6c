"""The sim-to-real gap of glsynth's cracks, with and without the camera model.

    .venv/bin/python bench/bench_sim2real.py --real /path/to/real --plain DATASET_A \
        --camera DATASET_B [--out out/bench-sim2real] [glsynth bench sim2real options]

DATASET_A and DATASET_B: the inspection preset (seed 0) generated without and with [sensor]
(`glsynth generate --preset inspection --seed 0`, and the same with `[sensor] enabled =
false` in --config for A). --real: a folder of real photographs with images/ and masks/
(CrackForest converted, for instance). Runs glsynth bench sim2real on both datasets at once
(one network each, and one on the real training share, all with the same seeds) and writes
bench/results/sim2real.json.
"""

import argparse
from pathlib import Path

from common import write_results
from glsynth.model.sim2real import Sim2RealSettings, run_sim2real, summary


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--real", required=True)
    p.add_argument("--plain", required=True, help="inspection dataset without the camera model")
    p.add_argument("--camera", required=True, help="inspection dataset with the camera model")
    p.add_argument("--out", default="out/bench-sim2real")
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--crop", type=int, default=128)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    settings = Sim2RealSettings(steps=args.steps, crop=args.crop, seed=args.seed)
    result = run_sim2real([args.plain, args.camera], args.real, args.out, settings)
    print(summary(result))
    write_results("sim2real", {"real_folder": Path(args.real).name,
                               "without_camera_model": Path(args.plain).name,
                               "with_camera_model": Path(args.camera).name, **result})

if __name__ == "__main__":
    main()
