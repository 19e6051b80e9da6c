"""What an orbit of one column needs to open, against a whole environment, in one run.

Three openings of the same environment, each in a fresh process (so the peak RSS is its own),
taken in turn `--repeats` times:
- "environment": as `glsynth render` opens it, for the preset's cameras;
- "orbit": as `glsynth fly` opens it, for an orbit's frames (culled to the parts in some
  frame's frustum, or that may shadow or hide the sky from one);
- "orbit, pixels only": a lower bound on any finer cull. An Embree ray cast through every
  pixel centre of every frame (made once, beforehand, and not timed) names the parts some
  pixel shows; only those get textures and damage maps, the rest keep their geometry
  (shadows and sky visibility need it) with flat materials.

The cast also counts the parts and the damaged columns the frames show, which says whether
an orbit can open in a quarter of an environment's time at all. After opening, the first
`--frames` views (the environment's sampled cameras, or the orbit's frames) are rendered with
every pass and timed, without writing files: a frame against a view at the same preset and
size.

    .venv/bin/python bench/bench_flight_open.py [--preset paper] [--env 0] [--column 4]
                                                [--standoff 4] [--heights 1.5,2.5]
                                                [--focal 50] [--repeats 3] [--frames 8]
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.world.cameras import Camera  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402
from glsynth.world.flights import plan_flight  # noqa: E402
from glsynth.world.visibility import visible_parts  # noqa: E402

CHILD = """
import dataclasses, json, resource, sys, time
import glsynth.render.view as render
from glsynth.appearance.materials import Materials
from glsynth.data.flight import flight_materials
from glsynth.render.view import EnvironmentView
sys.path.insert(0, sys.argv[2])
from bench_flight_open import orbit_config, orbit_cameras

args = json.loads(sys.argv[1])
mode, config = args["mode"], orbit_config(args)
cameras = None
if mode != "environment":
    cameras = orbit_cameras(config, args["env"])
    config = dataclasses.replace(config, materials=flight_materials(config.materials))
if mode == "pixels":
    seen = set(args["seen"])
    dress = render.dress

    def dress_seen(env, config, repository, bank, visible):
        dressing = dress(env, config, repository, bank, visible & seen)
        m = dressing.materials
        flat = {n: dataclasses.replace(m.factors(n), base_color_map=None, metallic_map=None,
                                       emissive_map=None, normal_map=None, damage_mask=None,
                                       zones=None, cracks=None)
                for n in m if n not in seen}
        # The product never swaps a deferred material's builder, so Materials has no public
        # way to hand one on: the bench reads it directly.
        ready = {n: m.factors(n) for n in m if n in seen and not m.is_deferred(n)}
        deferred = {n: m._deferred[n] for n in m if n in seen and m.is_deferred(n)}
        return dataclasses.replace(dressing, materials=Materials(ready | flat, deferred))

    render.dress = dress_seen
t0 = time.perf_counter()
view = EnvironmentView.open(config, args["seed"], args["env"], cameras=cameras)
opened = time.perf_counter() - t0
frame_s = []
if mode != "pixels":
    for i in range(args["frames"]):
        camera = view.camera(i).camera if cameras is None else cameras[i]
        t = time.perf_counter()
        view.renderer.render(camera)
        frame_s.append(time.perf_counter() - t)
print(json.dumps({"open_s": opened, "frame_s": frame_s, "parts_uploaded": len(view.scene.parts),
                  "damage_textures": sum(1 for a in view.dressing.assignments.values()
                                         if a.damage and a.damage.get("built")),
                  "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def orbit_config(args: dict) -> Config:
    """The preset with [flight] set to the bench's orbit."""
    config = load_config(args["preset"])
    return replace(config, flight=replace(
        config.flight, plan="orbit", column=args["column"], standoff_m=args["standoff"],
        heights_m=tuple(args["heights"]), focal_mm=args["focal"]))


def orbit_cameras(config: Config, env: int) -> list[Camera]:
    return plan_flight(build_environment(config, 0, env), config, validate=True).cameras(config)


def pixel_parts(config: Config, env: int) -> list[str]:
    """Names of the parts that some pixel centre of some orbit frame shows (Embree)."""
    import trimesh

    from glsynth.render.raycast import _intersector
    parts = build_environment(config, 0, env).parts
    scene = trimesh.util.concatenate([trimesh.Trimesh(p.world_vertices(), p.mesh.faces,
                                                      process=False) for p in parts])
    owner = np.repeat(np.arange(len(parts)), [len(p.mesh.faces) for p in parts])
    intersector = _intersector(scene)
    hit: set[int] = set()
    for camera in orbit_cameras(config, env):
        origin, rays = camera.rays()
        rays = rays.reshape(-1, 3)
        faces, _ = intersector.intersects_id(np.repeat(origin[None], len(rays), 0), rays,
                                             multiple_hits=False)[:2]
        hit |= set(owner[faces].tolist())
    return [parts[i].name for i in sorted(hit)]


def child(args: dict) -> dict:
    with tempfile.TemporaryDirectory() as tmp:  # the seen list can exceed argv's limits
        path = Path(tmp) / "args.json"
        path.write_text(json.dumps(args))
        code = CHILD.replace("json.loads(sys.argv[1])", f"json.load(open({str(path)!r}))")
        out = subprocess.run([sys.executable, "-c", code, "-", str(Path(__file__).parent)],
                             check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def counts(config: Config, env: int, names: set[str]) -> dict:
    parts = build_environment(config, 0, env).parts
    return {"parts": sum(p.name in names for p in parts),
            "by_component": dict(sorted(Counter(p.component.name.lower() for p in parts
                                                if p.name in names).items()))}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--env", type=int, default=0)
    parser.add_argument("--column", type=int, default=4)
    parser.add_argument("--standoff", type=float, default=4.0)
    parser.add_argument("--heights", default="1.5,2.5")
    parser.add_argument("--focal", type=float, default=50.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--frames", type=int, default=8,
                        help="views rendered after each opening (all passes), timed")
    a = parser.parse_args()
    args = {"preset": a.preset, "seed": 0, "env": a.env, "column": a.column,
            "standoff": a.standoff, "heights": [float(h) for h in a.heights.split(",")],
            "focal": a.focal, "frames": a.frames}
    config = orbit_config(args)
    t0 = time.perf_counter()
    seen = pixel_parts(config, a.env)
    cast_s = time.perf_counter() - t0
    frustum = visible_parts(build_environment(config, 0, a.env).parts,
                            orbit_cameras(config, a.env))
    modes = ("environment", "orbit", "pixels")
    child({**args, "mode": "environment"})  # warm the texture and damage-bank caches
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    for _ in range(a.repeats):
        for mode in modes:
            runs[mode].append(child({**args, "mode": mode, "seen": seen}))
    results = {"setting": args, "frames": len(orbit_cameras(config, a.env)),
               "size": [config.render.width, config.render.height],
               "environment_parts": counts(config, a.env, {p.name for p in build_environment(
                   config, 0, a.env).parts}),
               "in_some_frustum": counts(config, a.env, frustum),
               "shown_by_some_pixel": {**counts(config, a.env, set(seen)),
                                       "cast_s": round(cast_s, 1)}}
    for mode, items in runs.items():
        results[mode] = {
            "open_s": [round(r["open_s"], 2) for r in items],
            "open_s_median": round(statistics.median(r["open_s"] for r in items), 2),
            "peak_rss_mib": [round(r["peak_rss_mib"]) for r in items],
            "peak_rss_mib_median": round(statistics.median(r["peak_rss_mib"] for r in items)),
            "render_s_per_frame_median": (round(statistics.median(
                t for r in items for t in r["frame_s"]), 3) if items[0]["frame_s"] else None),
            "parts_uploaded": items[0]["parts_uploaded"],
            "damage_textures": items[0]["damage_textures"]}
    full = results["environment"]["open_s_median"]
    results["over_environment"] = {m: round(results[m]["open_s_median"] / full, 2)
                                   for m in ("orbit", "pixels")}
    results["frame_over_view"] = round(results["orbit"]["render_s_per_frame_median"] /
                                       results["environment"]["render_s_per_frame_median"], 2)
    write_results("flight_open", results)


if __name__ == "__main__":
    main()
