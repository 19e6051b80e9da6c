"""``glsynth bench blender``: one glsynth camera rendered by Blender Cycles (the paper's renderer)
and by glsynth, compared in time, component labels and depth.

Optional: Blender is found as ``blender`` on PATH (Debian package ``blender``) or given with
``--blender``; without it the command says so and measures nothing. The environment is
exported as glTF (only the parts glsynth uploads for that environment) and rendered in a
Blender subprocess by glsynth/render/blender_job.py, lit as glsynth lights it. Blender's
colour uses the export's flat preview materials, so its time is that of Cycles on this
geometry, not on the PBR textures; colour is not compared here (``glsynth bench quality`` does,
with the real materials). Damage labels are not compared either (the export has no damage masks).
"""

import dataclasses
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from glsynth.core.config import Config
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
from glsynth.core.labels import Component
from glsynth.render.cycles import camera_json, cycles_seed, run_job
from glsynth.render.export import describe_lighting, preview_materials
from glsynth.render.gltf import gltf_binary


def read_pass(path: Path, size: list[int]) -> np.ndarray:
    """First channel of a raw float32 RGBA image written bottom row first, top row first."""
    w, h = size
    return np.fromfile(path, np.float32).reshape(h, w, 4)[::-1, :, 0].copy()


def compare_labels_depth(component: np.ndarray, depth: np.ndarray,
                         blender_component: np.ndarray, blender_depth: np.ndarray,
                         zfar: float) -> dict:
    """Component agreement over all pixels (Blender's sky, id 0, counts as Nonbridge) and the
    depth difference relative to glsynth's where both hit geometry."""
    theirs = np.rint(blender_component).astype(np.int64)
    theirs[theirs == 0] = int(Component.NONBRIDGE)
    hit = (depth < zfar) & (blender_depth < zfar) & np.isfinite(blender_depth)
    rel = np.abs(blender_depth[hit] - depth[hit]) / depth[hit]
    return {"component_agreement": float((theirs == component).mean()),
            "depth_median_rel_diff": float(np.median(rel)) if rel.size else None,
            "depth_p99_rel_diff": float(np.quantile(rel, 0.99)) if rel.size else None,
            "pixels_hit_by_both": int(hit.sum())}


def bench_blender(config: Config, root_seed: int, env: int, camera_index: int,
                  samples: list[int], out: Path, blender: str, timeout_s: float) -> dict:
    from glsynth.render.view import EnvironmentView

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    view = EnvironmentView.open(config, root_seed, env)
    open_s = time.perf_counter() - t0
    try:
        # GL against Cycles, both without the camera model.
        placement, output = view.render(camera_index, photo=False)
        times = []
        for _ in range(3):
            t = time.perf_counter()
            view.render(camera_index, photo=False)
            times.append(time.perf_counter() - t)
    finally:
        view.renderer.release()
    shown = dataclasses.replace(view.environment, parts=tuple(
        p for p in view.environment.parts if p.name in view.scene.parts))
    glb = out / "scene.glb"
    atomic_write_bytes(glb, gltf_binary(shown.parts, preview_materials(shown.parts)))
    cam = placement.camera
    render = config.render
    job = {"mode": "bench", "glb": str(glb), "out": str(out), "samples": samples,
           "cameras": [camera_json(cam)],
           "seeds": [cycles_seed(root_seed, env, camera_index)],
           "lighting": describe_lighting(view.lighting)}
    t = time.perf_counter()
    blender_times = run_job(blender, job, out, timeout_s)
    process_s = time.perf_counter() - t
    sizes, version = blender_times.pop("sizes"), blender_times.pop("blender")
    passes = {name: read_pass(out / f"blender_{name}.f32", sizes[name])
              for name in ("labels", "depth")}
    for name in passes:
        (out / f"blender_{name}.f32").unlink()
    scores = compare_labels_depth(output.component, output.depth, passes["labels"],
                                  passes["depth"], render.zfar_m)
    glsynth_s = statistics.median(times)
    result = {
        "command": " ".join(["glsynth", *sys.argv[1:]]), "blender": version,
        "root_seed": root_seed, "env": env, "camera": camera_index,
        "size": [cam.width, cam.height],
        "glsynth": {"sample_s": glsynth_s, "environment_open_s": open_s,
                    "msaa": render.msaa, "shadow_map_px": render.shadow_map_px},
        "cycles": {"process_s": process_s, **blender_times,
                   "colour_over_glsynth_sample": {
                       n: s / glsynth_s for n, s in blender_times["colour_s"].items()}},
        "agreement": scores,
        "note": "glsynth sample_s: colour + labels + depth (median of 3 after one warm-up); "
                "Cycles colour on the export's flat materials; labels and depth from one "
                "1-sample emission render with the Z pass"}
    atomic_write_json(out / "blender.json", result)
    atomic_write_bytes(out / "blender.md", blender_table(result).encode())
    return result


def blender_table(result: dict) -> str:
    g, c, a = result["glsynth"], result["cycles"], result["agreement"]
    lines = ["| renderer | time per frame | x glsynth sample |", "|---|---|---|",
             f"| glsynth (colour + labels + depth, MSAA {g['msaa']}) | {g['sample_s']:.3f} s "
             "| 1 |"]
    lines += [f"| Cycles colour, {n} samples | {s:.2f} s | {s / g['sample_s']:.0f} |"
              for n, s in c["colour_s"].items()]
    lines.append(f"| Cycles labels + depth (1 sample, emission) | {c['labels_depth_s']:.2f} s "
                 f"| {c['labels_depth_s'] / g['sample_s']:.1f} |")
    depth = a["depth_median_rel_diff"]
    lines += ["", f"{result['blender']}; component labels agree on "
              f"{100 * a['component_agreement']:.2f} % of pixels; depth differs by "
              + (f"{depth:.1e} (median) and {a['depth_p99_rel_diff']:.1e} (99th percentile) "
                 "relative" if depth is not None else "nothing (no pixel hit by both)")
              + f" over {a['pixels_hit_by_both']} pixels hit by both."]
    return "\n".join(lines) + "\n"
