"""Time to build one environment (trajectory + all meshes) and to export it as .glb; under a
preset whose damage model is "mechanics", also to find every member's cracks (crack_segments,
what an inspection opening does before it places its cameras).

    .venv/bin/python bench/bench_environment.py [--preset NAME] [--envs 10] [--repeats 3]

Without --preset, the default config (the paper's world); the results file is
bench/results/environment.json, or environment_<preset>.json.
"""

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import summary, time_calls, write_results  # noqa: E402

from glsynth.appearance.dressing import crack_segments  # noqa: E402
from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.render.export import export_environment  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--preset", default=None, help="a preset name (default: Config())")
    args = parser.parse_args()
    config = Config() if args.preset is None else load_config(args.preset)
    build, export, cracks, triangles, parts = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for env in range(args.envs):
            build += time_calls(lambda env=env: build_environment(config, 0, env), args.repeats)
            built = build_environment(config, 0, env)
            triangles.append(sum(len(p.mesh.faces) for p in built.parts))
            parts.append(len(built.parts))
            export += time_calls(lambda built=built: export_environment(built, Path(tmp) / "s.glb"),
                                 args.repeats, warmup=0)
            if config.damage.model == "mechanics":
                cracks += time_calls(lambda built=built: crack_segments(built, config),
                                     args.repeats, warmup=0)
    found = {"crack_segments": summary(cracks)} if cracks else {}
    write_results("environment" if args.preset is None else f"environment_{args.preset}", {
        "build_environment": summary(build), "export_glb_and_json": summary(export), **found,
        "parts_per_environment": {"min": min(parts), "max": max(parts)},
        "triangles_per_environment": {"min": min(triangles), "max": max(triangles)},
    })


if __name__ == "__main__":
    main()
