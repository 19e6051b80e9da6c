"""Time to build one environment (trajectory + all meshes) and to export it as .glb.

    .venv/bin/python bench/bench_environment.py [--envs 10] [--repeats 3]
"""

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import summary, time_calls, write_results  # noqa: E402

from glsynth.core.config import Config  # noqa: E402
from glsynth.render.export import export_environment  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    config = Config()
    build, export, triangles, parts = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for env in range(args.envs):
            build += time_calls(lambda env=env: build_environment(config, 0, env), args.repeats)
            built = build_environment(config, 0, env)
            triangles.append(sum(len(p.mesh.faces) for p in built.parts))
            parts.append(len(built.parts))
            export += time_calls(lambda built=built: export_environment(built, Path(tmp) / "s.glb"),
                                 args.repeats, warmup=0)
    write_results("environment", {
        "build_environment": summary(build), "export_glb_and_json": summary(export),
        "parts_per_environment": {"min": min(parts), "max": max(parts)},
        "triangles_per_environment": {"min": min(triangles), "max": max(triangles)},
    })


if __name__ == "__main__":
    main()
