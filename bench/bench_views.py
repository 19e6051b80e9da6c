"""What the cameras see: keep rates by camera kind and removal reason (Section 3.4 filters), the
share of kept views showing each component, and component pixel shares, from colour,
component and depth renders at preview size.

- under each reading of the paper's camera placement ([cameras] placement and height_from,
  docs/design.md), at the configured exposure;
- for the default reading, at each exposure of --exposures (the dark filter depends on it);
- with --fence-heights, the default reading at each height of the fence on the deck edges (an
  assumed dimension): how much the fence hides the track, and how many regular cameras (of at
  least 100 environments) stand above the deck top at all; --only fence runs that sweep alone
  and writes views_fence.json;
- with --cycles-envs N, the same views of the first N environments path-traced by the Cycles
  twin, filtered at each exposure (Cycles' linear output is exposed exactly as GL's): whether
  the raster shortcut changes what the dark filter removes. Needs Blender.

    .venv/bin/python bench/bench_views.py [--preset paper] [--envs 12] [--width 384]
        [--exposures 1,1.41,2] [--cycles-envs 3] [--cycles-samples 32]
        [--fence-heights 1.5,1.1] [--only fence]
"""

import argparse
import dataclasses
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.checks import literal_choices  # noqa: E402
from glsynth.core.config import CameraConfig, Config, load_config  # noqa: E402
from glsynth.core.filters import removal_reason  # noqa: E402
from glsynth.core.labels import Component  # noqa: E402
from glsynth.data.statistics import PAPER  # noqa: E402
from glsynth.render.cycles import cycles_seed, render_linear, require_blender  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.tonemap import tone_map  # noqa: E402
from glsynth.render.view import EnvironmentView, preview_config  # noqa: E402
from glsynth.world.cameras import environment_camera  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402

CLASSES = [c for c in Component if c != Component.UNLABELLED]
KINDS = ("regular", "closeup")


def with_exposure(config: Config, exposure: float) -> Config:
    return dataclasses.replace(config, lighting=dataclasses.replace(config.lighting,
                                                                    exposure=exposure))


def view_records(config: Config, env: int, renderer: Renderer) -> list[dict]:
    """Per camera of environment ``env``: its kind, removal reason and component pixel counts."""
    view = EnvironmentView.open(config, 0, env, renderer)
    records = []
    for index in range(config.cameras.total):
        placement, out = view.render(index, frozenset({"color", "component", "depth"}))
        records.append({"kind": placement.kind,
                        "reason": removal_reason(out.color, out.component, out.depth),
                        "pixels": np.bincount(out.component.ravel(), minlength=len(Component))})
    return records


def summarize(records: list[dict]) -> dict:
    kinds = {k: {"views": 0, "kept": 0, "removed": {}} for k in KINDS}
    shows = {k: {c.name.lower(): 0 for c in CLASSES} for k in KINDS}
    pixels = np.zeros(len(Component), np.int64)
    for r in records:
        k = kinds[r["kind"]]
        k["views"] += 1
        if r["reason"] is not None:
            k["removed"][r["reason"]] = k["removed"].get(r["reason"], 0) + 1
            continue
        k["kept"] += 1
        pixels += r["pixels"]
        for c in CLASSES:
            shows[r["kind"]][c.name.lower()] += int(r["pixels"][c] > 0)
    kept = sum(k["kept"] for k in kinds.values())
    total = max(1, pixels[1:].sum())
    return {
        "keep_rate": {k: round(v["kept"] / max(1, v["views"]), 4) for k, v in kinds.items()},
        "views": kinds,
        "share_of_kept_views_showing": {
            **{k: {c: round(v / max(1, kinds[k]["kept"]), 4) for c, v in s.items()}
               for k, s in shows.items()},
            "all": {c.name.lower(): round(sum(s[c.name.lower()] for s in shows.values())
                                          / max(1, kept), 4) for c in CLASSES}},
        "component_pixel_share": {c.name.lower(): round(float(pixels[c] / total), 4)
                                  for c in CLASSES},
    }


def measure(config: Config, envs: int) -> dict:
    t0 = time.perf_counter()
    renderer = Renderer(config.render)
    records = [r for env in range(envs) for r in view_records(config, env, renderer)]
    renderer.release()
    result = summarize(records)
    result["seconds"] = round(time.perf_counter() - t0, 1)
    return result


def camera_heights(config: Config, envs: int) -> dict:
    """Where the regular cameras stand against the deck (no rendering): the track is in view
    only from above the deck top, so this bounds the share of views that can show a rail."""
    above, over = 0, 0
    for env in range(envs):
        trajectory = build_environment(config, 0, env).trajectory
        for index in range(config.cameras.n_regular):
            p = environment_camera(trajectory, config.cameras, config.render, 0, env, index)
            deck = trajectory.deck_at(np.array([p.s_m]))[0]
            if p.camera.pose[2, 3] > deck:
                above += 1
                over += p.distance_m < config.design.deck_width_m / 2
    n = max(1, envs * config.cameras.n_regular)
    return {"environments": envs, "regular_cameras": n,
            "above_deck_top": round(above / n, 4),
            "above_deck_top_and_over_the_deck": round(over / n, 4)}


def cycles_check(config: Config, envs: int, exposures: list[float], samples: int) -> dict:
    """GL and Cycles removals of the same views, at each exposure; the maps that the other
    filters read (component, depth) are GL's for both, as in a Cycles-twin dataset."""
    blender = require_blender()
    renderer = Renderer(config.render)
    gl = {e: [] for e in exposures}
    cycles = {e: [] for e in exposures}
    work = Path(tempfile.mkdtemp(prefix="glsynth-views-"))
    try:
        for env in range(envs):
            for e in exposures:
                view = EnvironmentView.open(with_exposure(config, e), 0, env, renderer)
                outs = [view.render(i, frozenset({"color", "component", "depth"}))
                        for i in range(config.cameras.total)]
                gl[e] += [(p.kind, removal_reason(o.color, o.component, o.depth))
                          for p, o in outs]
            # Labels and depth do not depend on the exposure: the last view's serve Cycles.
            placements = [p for p, _ in outs]
            linear = render_linear(
                [p for p in view.environment.parts if p.name in view.scene.parts],
                view.dressing.materials, view.lighting, [p.camera for p in placements],
                [cycles_seed(0, env, p.index) for p in placements], samples, work, blender).linear
            for e in exposures:
                cycles[e] += [(p.kind, removal_reason(tone_map(x, e), o.component, o.depth))
                              for (p, o), x in zip(outs, linear)]
    finally:
        renderer.release()
        shutil.rmtree(work, ignore_errors=True)
    out = {}
    for e in exposures:
        row = {}
        for kind in KINDS:
            g = [r for k, r in gl[e] if k == kind]
            c = [r for k, r in cycles[e] if k == kind]
            row[kind] = {
                "views": len(g),
                "keep_rate_gl": round(g.count(None) / len(g), 4),
                "keep_rate_cycles": round(c.count(None) / len(c), 4),
                "dark_gl": g.count("dark"), "dark_cycles": c.count("dark"),
                "dark_decision_agrees": sum((a == "dark") == (b == "dark") for a, b in zip(g, c))}
        out[f"exposure={e:g}"] = row
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--envs", type=int, default=6)
    parser.add_argument("--width", type=int, default=384)
    parser.add_argument("--exposures", default="1,1.41,2",
                        help="comma-separated exposures for the default reading")
    parser.add_argument("--cycles-envs", type=int, default=0)
    parser.add_argument("--cycles-samples", type=int, default=32)
    parser.add_argument("--fence-heights", default="",
                        help="comma-separated fence heights in metres for the default reading")
    parser.add_argument("--only", choices=("fence",), help="run this sweep alone")
    args = parser.parse_args()
    exposures = [float(x) for x in args.exposures.split(",")]
    fences = [float(x) for x in args.fence_heights.split(",") if x]
    if args.only == "fence" and not fences:
        parser.error("--only fence needs --fence-heights, e.g. --fence-heights 1.5,1.1")
    base = preview_config(load_config(args.preset), args.width)
    results = {"paper": {"keep_rate": PAPER["keep_rate"]}, "envs": args.envs,
               "size": [base.render.width, base.render.height],
               "exposure": base.lighting.exposure, "readings": {}, "exposures": {}}
    if fences:
        results["fence_heights"] = {}
        for height in fences:
            config = dataclasses.replace(base, design=dataclasses.replace(
                base.design, fence_height_m=height))
            results["fence_heights"][f"fence_height_m={height:g}"] = measure(config, args.envs)
            print(f"fence_height_m={height:g}",
                  results["fence_heights"][f"fence_height_m={height:g}"]
                  ["share_of_kept_views_showing"]["all"], flush=True)
        results["regular_camera_heights"] = camera_heights(base, max(args.envs, 100))
        print(results["regular_camera_heights"], flush=True)
    if args.only == "fence":
        write_results("views_fence", results)
        return
    for placement in literal_choices(CameraConfig, "placement"):
        for height_from in literal_choices(CameraConfig, "height_from"):
            name = f"placement={placement}, height_from={height_from}"
            config = dataclasses.replace(base, cameras=dataclasses.replace(
                base.cameras, placement=placement, height_from=height_from))
            results["readings"][name] = measure(config, args.envs)
            print(name, results["readings"][name]["keep_rate"], flush=True)
    default = results["readings"][
        f"placement={base.cameras.placement}, height_from={base.cameras.height_from}"]
    for e in exposures:
        results["exposures"][f"exposure={e:g}"] = (
            default if e == base.lighting.exposure else measure(with_exposure(base, e),
                                                                args.envs))
        print(f"exposure={e:g}", results["exposures"][f"exposure={e:g}"]["keep_rate"],
              flush=True)
    if args.cycles_envs:
        t0 = time.perf_counter()
        results["cycles"] = {"envs": args.cycles_envs, "samples": args.cycles_samples,
                             **cycles_check(base, args.cycles_envs, exposures,
                                            args.cycles_samples)}
        results["cycles"]["seconds"] = round(time.perf_counter() - t0, 1)
    write_results("views", results)


if __name__ == "__main__":
    main()
