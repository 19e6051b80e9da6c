"""Cracks: how well widths are measured back from rendered label maps, what the crack code
costs per sample, and what opening an environment costs at the paper and inspection presets.

    .venv/bin/python bench/bench_cracks.py [--skip-open]

1. Width measurement (glsynth.assess.cracks) on GL renders of straight cracks on a plane
   0.5 m from a camera with fx = width (0.78 mm pixels at 640 px; widths up to 6 px =
   4.7 mm): the error at each measured skeleton pixel against the rendered crack-width map,
   by the crack's width in pixels
   (fronto-parallel, four orientations each) and by the plane's angle to the view (4 px
   cracks). Writes bench/results/cracks.png (the plot) beside cracks.json.
2. Cost: one 960x540 view of a plane filling it, with 0 to 160 cracks across it, at the
   default render settings; median of 11 renders each.
3. Opening: environment 0 at the paper and inspection presets, each in a fresh process
   (after a warm-up process that fills the texture and damage caches): wall time and peak RSS.
4. The issue's goal on the inspection preset: every view of environments 0 to --envs - 1 at
   full size (1920x1080), its cracks measured back by the code `glsynth assess --oracle` runs
   and compared with the rendered crack-width map; the median errors over skeleton pixels
   whose true width is at least 2 px, and how many cracks and pixels that covers. (The
   dataset's 640x360 maps hold few inspection cracks 2 px wide: most are sub-pixel there.)
5. The picture in the README (`--picture`, alone): of the inspection preset's 96 views, the
   one with the most crack pixels at least 1.5 px wide, cropped around them at full size:
   image | damage labels | crack-width map (bench/results/cracks_inspection.png).
"""

import argparse
import dataclasses
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import matplotlib
import numpy as np
import trimesh
from trimesh.visual import TextureVisuals

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, write_results  # noqa: E402

from glsynth.appearance.cracks import CrackNetwork  # noqa: E402
from glsynth.appearance.materials import Material  # noqa: E402
from glsynth.assess.cracks import Intrinsics, error_summary, measure_cracks, width_errors  # noqa: E402
from glsynth.core.config import LightingConfig, RenderConfig, load_config  # noqa: E402
from glsynth.data.visible_cracks import on_surface  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.scene import build_scene  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402
from glsynth.world.cameras import Camera  # noqa: E402
from glsynth.world.environment import Part, PartKind  # noqa: E402
from glsynth.world.lighting import environment_lighting  # noqa: E402

LIGHT = environment_lighting(LightingConfig(sun_elevation_deg=(50.0, 50.0),
                                            sun_azimuth_deg=(30.0, 30.0)), 0, 0)
WIDTHS_PX = (0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)
DISTANCE_M = 0.5
ANGLES_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 70.0)
ORIENTATIONS_DEG = (5.0, 30.0, 55.0, 80.0)


def plane(normal_angle_deg: float, half: float = 2.0) -> tuple[trimesh.Trimesh, np.ndarray,
                                                                  np.ndarray, np.ndarray]:
    """A plane through (0, 0, -DISTANCE_M) turned about the y axis by the angle; its mesh (UVs
    in metres), centre, and unit vectors along it (u across the image, v up)."""
    a = np.radians(normal_angle_deg)
    centre = np.array([0.0, 0.0, -DISTANCE_M])
    u = np.array([np.cos(a), 0.0, np.sin(a)])
    v = np.array([0.0, 1.0, 0.0])
    corners = np.array([centre + s * half * u + t * half * v
                        for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    mesh = trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]], process=False)
    mesh.visual = TextureVisuals(uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) * half)
    return mesh, centre, u, v


def cracks_across(centre: np.ndarray, u: np.ndarray, v: np.ndarray, width_m: float,
                  orientations_deg: tuple[float, ...], spacing_m: float) -> CrackNetwork:
    """One straight crack per orientation, side by side along u, 0.2 m long each."""
    points = []
    for k, angle in enumerate(orientations_deg):
        a = np.radians(angle)
        mid = centre + (k - (len(orientations_deg) - 1) / 2) * spacing_m * u
        half = 0.1 * (np.cos(a) * u + np.sin(a) * v)
        points.append([mid - half, mid + half])
    n = len(points)
    return CrackNetwork(np.array(points), np.full((n, 2), width_m), np.arange(n, dtype=np.int32),
                        ("flexural",) * n)


def render(renderer: Renderer, mesh: trimesh.Trimesh, cracks: CrackNetwork | None,
           camera: Camera):
    part = Part("wall", PartKind.COLUMN, None, mesh, np.eye(4))
    renderer.load(build_scene([part], {"wall": Material(base_color=(0.3, 0.3, 0.3, 1.0),
                                                        cracks=cracks)}), LIGHT)
    return renderer.render(camera)


def measured(renderer: Renderer, camera: Camera, angle_deg: float, width_m: float,
             spacing_m: float) -> dict:
    mesh, centre, u, v = plane(angle_deg)
    out = render(renderer, mesh, cracks_across(centre, u, v, width_m, ORIENTATIONS_DEG,
                                               spacing_m), camera)
    measure = measure_cracks(out.damage, out.depth, Intrinsics.centred(camera.fx,
                                                                       out.damage.shape))
    return width_errors(measure, out.crack_width)


def accuracy() -> dict:
    width, height = 640, 480
    camera = Camera(width, height, 36.0, 36.0, np.eye(4), 0.05, 100.0)
    pixel_m = DISTANCE_M / camera.fx
    rows = {"by_width_px": {}, "by_angle_deg": {}}
    with Renderer(dataclasses.replace(RenderConfig(), width=width, height=height)) as r:
        for w_px in WIDTHS_PX:
            rows["by_width_px"][w_px] = error_summary([measured(r, camera, 0.0, w_px * pixel_m,
                                                                0.06)])
        for angle in ANGLES_DEG:
            rows["by_angle_deg"][angle] = error_summary([measured(r, camera, angle,
                                                                  4 * pixel_m, 0.06)])
    rows["pixel_mm"] = 1000 * pixel_m
    return rows


def plot(rows: dict, path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, key, label in ((axes[0], "by_width_px", "crack width [px]"),
                           (axes[1], "by_angle_deg", "plane angle to the view [deg]")):
        xs = [float(x) for x in rows[key]]
        rel = [100 * (s["all"]["median_relative_error"] or np.nan) for s in rows[key].values()]
        ax.plot(xs, rel, "o-")
        ax.axhline(10, color="grey", lw=0.8, ls="--")
        ax.set_xlabel(label)
        ax.set_ylabel("median |error| / width [%]")
        ax.set_ylim(bottom=0)
    axes[0].set_xscale("log")
    fig.suptitle("Crack widths measured back from GL label maps (glsynth.assess.cracks)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def cost() -> dict:
    width, height = 960, 540
    camera = Camera(width, height, 36.0, 36.0, np.eye(4), 0.05, 100.0)
    mesh, centre, u, v = plane(0.0)
    out = {}
    with Renderer(dataclasses.replace(RenderConfig(), width=width, height=height)) as r:
        for count in (0, 10, 40, 160):
            orientations = tuple(np.linspace(60.0, 120.0, count)) if count else ()
            cracks = (cracks_across(centre, u, v, 0.5e-3, orientations, 0.9 / max(count, 1))
                      if count else None)
            render(r, mesh, cracks, camera)  # the load and a first draw
            times = []
            for _ in range(11):
                t0 = time.perf_counter()
                r.render(camera)
                times.append(time.perf_counter() - t0)
            out[count] = round(1e3 * statistics.median(times), 1)
    return {"size": [width, height], "render_ms_median_by_cracks": out}


OPEN = """
import resource, sys, time
from glsynth.core.config import load_config
from glsynth.render.view import EnvironmentView
t0 = time.perf_counter()
view = EnvironmentView.open(load_config(sys.argv[1]), 0, 0)
seconds = time.perf_counter() - t0
view.renderer.release()
print(seconds, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""


def opening() -> dict:
    out = {}
    for preset in ("inspection", "paper"):
        run = [sys.executable, "-c", OPEN, preset]
        subprocess.run(run, check=True, capture_output=True)  # fills the caches on disk
        seconds, rss = subprocess.run(run, check=True, capture_output=True, text=True
                                      ).stdout.split()
        out[preset] = {"open_s": round(float(seconds), 2), "peak_rss_mib": round(float(rss))}
    return out


def segments_measured(view: EnvironmentView, camera: Camera, out, measure) -> np.ndarray:
    """(S, 2) per crack segment of the view measured at a skeleton pixel whose true width is
    at least 2 px: the median true and measured widths [mm] over those of its skeleton pixels
    (within one pixel of its centreline samples on the rendered surface)."""
    truth_px = out.crack_width * camera.fx / (1000.0 * np.maximum(out.depth, 1e-9))
    wide = np.isfinite(measure.skeleton_width_mm) & (out.crack_width > 0) & (truth_px >= 2)
    h, w = wide.shape
    pairs = []
    for ordinal, part in enumerate(view.environment.parts):
        if part.name not in view.dressing.materials:
            continue
        net = view.dressing.materials.factors(part.name).cracks
        if net is None or not len(net.points):
            continue
        row, col, segment, _, on = on_surface(net, part, camera, out.depth)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                r, c = row[on] + dr, col[on] + dc
                ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
                hit = ok.copy()
                hit[ok] = wide[r[ok], c[ok]]
                key = ordinal * 10**7 + segment[on][hit]
                pairs.append(np.stack([key, r[hit] * w + c[hit]], 1))
    if not pairs or not sum(len(p) for p in pairs):
        return np.zeros((0, 2))
    pairs = np.unique(np.concatenate(pairs), axis=0)
    truth, measured = out.crack_width.ravel(), measure.skeleton_width_mm.ravel()
    return np.array([[np.median(truth[pairs[pairs[:, 0] == k, 1]]),
                      np.median(measured[pairs[pairs[:, 0] == k, 1]])]
                     for k in np.unique(pairs[:, 0])])


def inspection_goal(envs: int) -> dict:
    """Part 4 over environments 0 .. envs - 1 of the inspection preset."""
    config = load_config("inspection")
    errors, segments, views, wide_cracks = [], [], 0, 0
    for env in range(envs):
        view = EnvironmentView.open(config, 0, env)
        try:
            for index in range(config.cameras.total):
                placement, out = view.render(index, frozenset({"damage", "depth"}))
                if not out.crack_width.any():
                    continue
                measure = measure_cracks(out.damage, out.depth,
                                         Intrinsics.of_map(placement.camera.K))
                errors.append(width_errors(measure, out.crack_width))
                segments.append(segments_measured(view, placement.camera, out, measure))
                # The measured cracks holding a skeleton pixel of true width >= 2 px (the
                # pixels width_errors compares, in its order).
                on = np.isfinite(measure.skeleton_width_mm) & (out.crack_width > 0)
                ids = measure.labels[on][errors[-1]["truth_px"] >= 2]
                wide_cracks += len(np.unique(ids))
                views += 1
        finally:
            view.renderer.release()
    summary = error_summary(errors)
    summary["environments"] = envs
    summary["views"] = envs * config.cameras.total
    summary["views_with_cracks"] = views
    summary["views_with_a_crack_of_2px"] = sum(bool((e["truth_px"] >= 2).any()) for e in errors)
    summary["measured_cracks_with_2px"] = wide_cracks
    pooled = np.concatenate(segments) if segments else np.zeros((0, 2))
    error = np.abs(pooled[:, 1] - pooled[:, 0])
    summary["segments_with_2px"] = {
        "segments": len(pooled),
        "median_abs_error_mm": float(np.median(error)) if len(pooled) else None,
        "median_relative_error": float(np.median(error / pooled[:, 0])) if len(pooled) else None}
    return summary


def picture(path: Path, crop: tuple[int, int] = (480, 270)) -> dict:
    from glsynth.core.fileio import png_bytes
    from glsynth.core.palette import DAMAGE_RGB, overlay

    def wide(placement, out) -> np.ndarray:
        """Crack pixels at least 1.5 px wide: cracks the colour image shows."""
        return out.crack_width >= 1.5 * 1000 * out.depth / placement.camera.fx

    config = load_config("inspection")
    best = (-1, None, None, None)
    for env in range(config.dataset.n_environments):
        view = EnvironmentView.open(config, 0, env)
        try:
            for index in range(config.cameras.total):
                placement, out = view.render(index)
                count = int(wide(placement, out).sum())
                if count > best[0]:
                    best = (count, env, placement, out)
        finally:
            view.renderer.release()
    _, env, placement, out = best
    rows, cols = np.nonzero(wide(placement, out))
    w, h = crop
    top = int(np.clip(np.median(rows) - h // 2, 0, out.crack_width.shape[0] - h))
    left = int(np.clip(np.median(cols) - w // 2, 0, out.crack_width.shape[1] - w))
    box = (slice(top, top + h), slice(left, left + w))
    widest = config.damage.crack_width_mm[1]
    widths = np.clip(out.crack_width[box] / widest, 0, 1)  # the scale ends at the widest crack
    scale = (plt.get_cmap("inferno")(widths)[..., :3] * 255).astype(np.uint8)
    scale[out.crack_width[box] == 0] = 0
    panels = [out.color[box], overlay(out.color[box], out.damage[box], DAMAGE_RGB, 0.8,
                                      skip=(1,)), scale]
    path.write_bytes(png_bytes(np.concatenate(panels, axis=1)))
    return {"env": env, "camera": placement.index, "crop": [left, top, w, h],
            "max_width_mm": float(out.crack_width.max()), "focal_mm": placement.camera.focal_mm}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-open", action="store_true", help="leave out part 3")
    parser.add_argument("--envs", type=int, default=4, help="part 4: inspection environments")
    parser.add_argument("--picture", action="store_true", help="only part 5, the picture")
    parser.add_argument("--goal-only", action="store_true", help="only part 4, the goal")
    args = parser.parse_args()
    if args.picture:
        print(picture(RESULTS / "cracks_inspection.png"))
        return
    if args.goal_only:
        write_results("cracks_goal", json.loads(json.dumps(inspection_goal(args.envs))))
        return
    rows = accuracy()
    plot(rows, RESULTS / "cracks.png")
    results = {"accuracy": rows, "cost": cost(), "inspection_goal": inspection_goal(args.envs)}
    if not args.skip_open:
        results["opening"] = opening()
    write_results("cracks", json.loads(json.dumps(results, default=str)))


if __name__ == "__main__":
    main()
