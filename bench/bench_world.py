"""What the town around the viaducts costs a demo sample: [environment] world = "panels"
(the paper's) against "town", side by side in one process with one renderer.

For each environment, in turn for both worlds (alternating which goes first, so drift in the
machine's speed falls on both): building the environment, opening it (build, dressing,
upload), and rendering every sampled camera as generate does (the photograph included). The
demo preset's other settings are left as they are; the town's textures and the repository are
warmed up first, so no world pays for a first use.

    .venv/bin/python bench/bench_world.py [--envs 2]
"""

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402

WORLDS = ("panels", "town")


def _config(world: str) -> Config:
    config = load_config("demo")
    return dataclasses.replace(config, environment=dataclasses.replace(config.environment,
                                                                       world=world))


def _one(config: Config, env: int, renderer: Renderer) -> dict[str, float]:
    t0 = time.perf_counter()
    built = build_environment(config, 0, env)
    t1 = time.perf_counter()
    view = EnvironmentView.open(config, 0, env, renderer=renderer)
    t2 = time.perf_counter()
    for index in range(config.cameras.total):
        view.render(index)
    t3 = time.perf_counter()
    triangles = sum(len(p.mesh.faces) for p in built.parts)
    return {"build_s": t1 - t0, "open_s": t2 - t1, "render_s": t3 - t2,
            "sample_s": (t3 - t1) / config.cameras.total, "parts": len(built.parts),
            "triangles": triangles}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=2)
    args = parser.parse_args()
    configs = {w: _config(w) for w in WORLDS}
    runs: dict[str, list[dict[str, float]]] = {w: [] for w in WORLDS}
    with Renderer(configs["town"].render) as renderer:
        EnvironmentView.open(configs["town"], 0, 0, renderer=renderer)  # warm caches
        for env in range(args.envs):
            order = WORLDS if env % 2 == 0 else WORLDS[::-1]
            for world in order:
                runs[world].append(_one(configs[world], env, renderer))
                print(world, env, runs[world][-1], flush=True)
    medians = {w: {k: statistics.median(r[k] for r in runs[w]) for k in runs[w][0]}
               for w in WORLDS}
    ratios = {k: medians["town"][k] / medians["panels"][k]
              for k in ("build_s", "open_s", "render_s", "sample_s")}
    write_results("world", {"envs": args.envs, "cameras": configs["town"].cameras.total,
                            "runs": runs, "medians": medians, "town_over_panels": ratios})


if __name__ == "__main__":
    main()
