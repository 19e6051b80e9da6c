"""Digests of rendered bytes at the paper preset, to show that a refactoring changes no byte.

    .venv/bin/python bench/bench_digests.py --out bench/results/digests_before.json
    .venv/bin/python bench/bench_digests.py --compare bench/results/digests_before.json

Renders ``--cameras`` views (default 8, spread over the environment's cameras) of environment
``--env`` at the paper preset, at MSAA 4 (the preset's) and MSAA 0, every pass, and records the
sha256 of each pass's array. ``--compare`` renders again and lists every view and pass whose
bytes differ (exit 1 if any does). llvmpipe's output may differ between processors, so compare
digests made on the same machine.
"""

import argparse
import dataclasses
import hashlib
import json
import sys
from pathlib import Path

from glsynth.core.config import load_config
from glsynth.render.view import EnvironmentView


def digests(env: int, n_cameras: int) -> dict[str, str]:
    base = load_config("paper")
    out = {}
    for msaa in (base.render.msaa, 0):
        config = dataclasses.replace(base, render=dataclasses.replace(base.render, msaa=msaa))
        view = EnvironmentView.open(config, 0, env)
        total = config.cameras.total
        cameras = sorted({round(i * (total - 1) / max(1, n_cameras - 1))
                          for i in range(n_cameras)})
        try:
            for index in cameras:
                _, output = view.render(index)
                for name, field in dataclasses.asdict(output).items():
                    digest = hashlib.sha256(field.tobytes()).hexdigest()
                    out[f"msaa{msaa}/camera{index:03d}/{name}"] = digest
        finally:
            view.renderer.release()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", type=int, default=0)
    parser.add_argument("--cameras", type=int, default=8)
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", help="write the digests here (JSON)")
    group.add_argument("--compare", help="digests written earlier by --out")
    args = parser.parse_args()
    now = digests(args.env, args.cameras)
    if args.out:
        payload = {"command": "python " + " ".join(sys.argv), "env": args.env, "digests": now}
        Path(args.out).write_text(json.dumps(payload, indent=2) + "\n")
        print(f"{len(now)} digests -> {args.out}")
        return 0
    before = json.loads(Path(args.compare).read_text())["digests"]
    differ = sorted(k for k in before if before[k] != now.get(k))
    for key in differ:
        print(f"differs: {key}")
    # Outputs added since (such as crack_width) have nothing to compare with.
    added = sorted(now.keys() - before.keys())
    if added:
        print(f"{len(added)} arrays new since {args.compare}, not compared: "
              f"{', '.join(sorted({k.rsplit('/', 1)[1] for k in added}))}")
    print(f"{len(before) - len(differ)} of {len(before)} arrays identical to {args.compare}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
