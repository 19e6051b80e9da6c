"""Face views of the inspection preset under Section 3.4's filters and under the preset's.

    .venv/bin/python bench/bench_inspection.py --envs 3

Renders every camera of environments 0 .. envs-1 (seed 0) at the inspection preset's full
size and counts, for the paper's [filters] and the preset's, the views each keeps and why it
removes the others, and the RRDR's share of the bridge pixels of the kept views. Also the
draws the face placement needed. Writes bench/results/inspection.json (docs/design.md,
"Inspection preset", quotes it).
"""

import argparse
import collections

import numpy as np
from common import write_results

from glsynth.core.config import FiltersConfig, load_config
from glsynth.core.filters import removal_reason, view_rrdr
from glsynth.core.labels import Component
from glsynth.render.view import EnvironmentView


def measure(n_envs: int) -> dict:
    config = load_config("inspection")
    rules = {"paper": FiltersConfig(), "inspection": config.filters}
    removed = {name: collections.Counter() for name in rules}
    share = {name: [] for name in rules}
    tries, members, renderer = [], collections.Counter(), None
    for env in range(n_envs):
        view = EnvironmentView.open(config, 0, env, renderer)
        renderer = view.renderer
        parts = {p.name: p for p in view.environment.parts}
        for index in range(config.cameras.total):
            placement, out = view.render(index)
            tries.append(placement.face.tries)
            members[parts[placement.face.member].component.name.lower()] += 1
            bridge = out.component > Component.NONBRIDGE
            for name, rule in rules.items():
                reason = removal_reason(out.color, out.component, out.depth, rule)
                removed[name][reason or "kept"] += 1
                if reason is None:
                    reliable = view_rrdr(rule, out.depth, placement.camera.fx) & bridge
                    share[name].append(float(reliable.sum() / max(1, bridge.sum())))
    renderer.release()
    views = len(tries)
    return {"environments": n_envs, "views": views, "members": dict(members),
            "first_draw_share": float(np.mean(np.array(tries) == 1)), "max_draws": max(tries),
            **{name: {"kept": removed[name]["kept"], "keep_rate": removed[name]["kept"] / views,
                      "removed": {r: n for r, n in removed[name].items() if r != "kept"},
                      "mean_rrdr_share_of_bridge_pixels": float(np.mean(share[name])),
                      "views_with_rrdr_pixels": sum(s > 0 for s in share[name])}
               for name in rules}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=3)
    write_results("inspection", measure(parser.parse_args().envs))


if __name__ == "__main__":
    main()
