"""COLMAP on a glsynth flight: do the textures carry enough detail for multi-view work?

Flies an orbit with `glsynth fly`, then runs COLMAP itself (pycolmap, the [flights] extra) on
its colour images alone: SIFT features, sequential matching (each frame with the next
`--overlap` in flight order; no loop detection, which needs a vocabulary tree), then
- the point triangulator with the exact poses (sparse/0 without its points): the distance of
  each triangulated point to the true surfaces (exact point-to-triangle distance over the
  environment's meshes; beyond --margin counts as an outlier) as median and 90th percentile,
  and the share of points on each component (the nearest part's);
- the incremental mapper from scratch: the share of frames it registers (largest model), and
  after a similarity alignment of its camera centres to the truth, the rotation and position
  errors.

    .venv/bin/python bench/bench_flight.py [--size 960x540] [--standoff 2] [--focal 50]
                                           [--heights 1.5,3.0]
                                           [--overlap 10] [--texture-size 512]
                                           [--concrete-scale 0.1,1.0] [--label L]
                                           [--concrete-detail flights|off]
                                           [--exposure metered|scene] [--refine-intrinsics]
                                           [--out /tmp/glsynth-bench-flight]

It also draws bench/results/flight/flight.png: three frames with their labels, and the point
cloud seen from outside the orbit, coloured by component. The issue's setting, a 5 m orbit,
is refused: from 4.5 m the ring comes within the 1 m clearance of the next column along the
track (columns stand 6 m apart both ways); 4 m (100 frames at 80 % overlap) is the widest.
Skips, saying so, where pycolmap is not installed.
"""

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, write_results  # noqa: E402

from glsynth.cli import main as glsynth  # noqa: E402
from glsynth.core.config import load_config  # noqa: E402
from glsynth.core.fileio import atomic_write_bytes, png_bytes  # noqa: E402
from glsynth.core.labels import Component  # noqa: E402
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, overlay  # noqa: E402
from glsynth.data.flight_export import project, read_ply  # noqa: E402
from glsynth.world.cameras import Camera  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402
from glsynth.world.flights import look_pose, surface_distance  # noqa: E402
from glsynth.world.lens import Lens  # noqa: E402


def fly(args: argparse.Namespace, out: Path) -> Path:
    width, height = (int(v) for v in args.size.split("x"))
    toml = out.parent / f"{out.name}.toml"
    toml.write_text(f"[render]\nwidth = {width}\nheight = {height}\n[materials]\n"
                    f"texture_size = {args.texture_size}\n"
                    f"builtin_size = {max(1024, args.texture_size)}\n"
                    f"concrete_scale = [{args.concrete_scale}]\n"
                    f"concrete_detail = \"{args.concrete_detail}\"\n"
                    "[flight]\nplan = \"orbit\"\n"
                    f"column = {args.column}\nstandoff_m = {args.standoff}\n"
                    f"heights_m = [{args.heights}]\nfocal_mm = {args.focal}\n"
                    "forward_overlap_pct = 80.0\n"
                    f"exposure = \"{args.exposure}\"\n")
    code = glsynth(["fly", "--preset", "paper", "--seed", str(args.seed), "--env",
                    str(args.env), "--config", str(toml), "--out", str(out)])
    if code:
        raise SystemExit(f"glsynth fly failed ({code})")
    return toml


def posed_model(pycolmap, out: Path, work: Path, database: Path) -> Path:
    """sparse/0 with its cameras and poses but no points, its images numbered as the
    database numbers them (by name): COLMAP's input for triangulating from known poses (each
    image's second line empty, points3D.txt empty)."""
    posed = work / "posed"
    posed.mkdir(parents=True, exist_ok=True)
    shutil.copy(out / "sparse" / "0" / "cameras.txt", posed / "cameras.txt")
    db = pycolmap.Database.open(database)
    ids = {image.name: image.image_id for image in db.read_all_images()}
    db.close()
    lines = [x for x in (out / "sparse" / "0" / "images.txt").read_text().splitlines()
             if not x.startswith("#")]
    posed_lines = []
    for pose in lines[0::2]:
        fields = pose.split()
        posed_lines += [" ".join([str(ids[fields[-1]]), *fields[1:]]), ""]
    (posed / "images.txt").write_text("\n".join(posed_lines) + "\n")
    (posed / "points3D.txt").write_text("")
    return posed


def features(pycolmap, out: Path, work: Path, names: list[str], overlap: int) -> Path:
    database = work / "database.db"
    database.unlink(missing_ok=True)
    cam = (out / "sparse" / "0" / "cameras.txt").read_text().splitlines()[1].split()
    reader = pycolmap.ImageReaderOptions(camera_model=cam[1], camera_params=",".join(cam[4:]))
    pycolmap.extract_features(database, out, image_names=names,
                              camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader)
    pairing = pycolmap.SequentialPairingOptions(overlap=overlap, loop_detection=False)
    pycolmap.match_sequential(database, pairing_options=pairing)
    return database


def match_stats(pycolmap, database: Path) -> dict:
    """SIFT keypoints per frame and verified (geometric) inlier matches between frames one
    and two apart in flight order, as medians (and the least keypoints)."""
    db = pycolmap.Database.open(database)
    try:
        frame = {im.image_id: int(Path(im.name).parent.name.split("_")[1])
                 for im in db.read_all_images()}
        keypoints = [db.read_keypoints(i).shape[0] for i in frame]
        inliers: dict[tuple[int, int], int] = {}
        for pair, geometry in zip(*db.read_two_view_geometries(), strict=True):
            a, b = sorted(frame[i] for i in pycolmap.pair_id_to_image_pair(pair))
            inliers[(a, b)] = geometry.inlier_matches.shape[0]
    finally:
        db.close()
    n = len(frame)
    return {"keypoints_per_frame_median": float(np.median(keypoints)),
            "keypoints_per_frame_min": int(min(keypoints)),
            **{f"inliers_to_frame_plus_{k}_median": float(np.median(
                [inliers.get((i, i + k), 0) for i in range(n - k)])) for k in (1, 2)}}


def nearest_surfaces(env, points: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Distance of each point to the nearest part's surface (inf beyond ``margin`` of every
    part's box) and that part's component id."""
    best = np.full(len(points), np.inf)
    component = np.zeros(len(points), int)
    for part in env.parts:
        corners = part.world_vertices()
        lo, hi = corners.min(0) - margin, corners.max(0) + margin
        near = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
        triangles = part.mesh.triangles @ part.pose[:3, :3].T + part.pose[:3, 3]
        for chunk in np.array_split(near, max(1, len(near) * len(triangles) // 2_000_000)):
            if chunk.size:
                d = surface_distance(triangles, points[chunk])
                better = d < best[chunk]
                best[chunk[better]], component[chunk[better]] = d[better], int(part.component)
    return best, component


def triangulation(pycolmap, env, out: Path, work: Path, database: Path, margin: float) -> dict:
    model = pycolmap.Reconstruction(str(posed_model(pycolmap, out, work, database)))
    tri = work / "triangulated"
    tri.mkdir(exist_ok=True)
    model = pycolmap.triangulate_points(model, database, out, tri)
    xyz = np.array([p.xyz for p in model.points3D.values()])
    if not len(xyz):
        return {"points": 0}
    dist, component = nearest_surfaces(env, xyz, margin)
    near = dist[np.isfinite(dist)]
    shares = {Component(c).name.lower(): float(np.mean(component[np.isfinite(dist)] == c))
              for c in np.unique(component[np.isfinite(dist)])}
    return {"points": len(xyz), "outliers_beyond_margin": int(np.sum(~np.isfinite(dist))),
            "median_distance_mm": 1000 * float(np.median(near)),
            "p90_distance_mm": 1000 * float(np.percentile(near, 90)),
            "mean_track_length": float(np.mean([p.track.length()
                                                for p in model.points3D.values()])),
            "share_by_component": shares}


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = (np.trace(a @ b.T) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def mapping(pycolmap, out: Path, work: Path, database: Path, n_frames: int,
            refine_intrinsics: bool) -> dict:
    mapped = work / "mapped"
    shutil.rmtree(mapped, ignore_errors=True)
    mapped.mkdir()
    # The flight's intrinsics are exact (cameras.txt); refined from an orbit, COLMAP lets the
    # PINHOLE camera's fy drift (2-6x fx measured), which no texture can fix.
    options = pycolmap.IncrementalPipelineOptions(
        ba_refine_focal_length=refine_intrinsics, ba_refine_principal_point=False,
        ba_refine_extra_params=refine_intrinsics)
    models = pycolmap.incremental_mapping(database, out, mapped, options=options)
    if not models:
        return {"registered_share": 0.0}
    model = max(models.values(), key=lambda m: m.num_reg_images())
    truth = pycolmap.Reconstruction(str(out / "sparse" / "0"))
    by_name = {im.name: im for im in truth.images.values()}
    pairs = [(im, by_name[im.name]) for im in model.images.values() if im.has_pose]
    result = {"registered_share": len(pairs) / n_frames, "models": len(models)}
    if len(pairs) < 3:  # too few to align
        return result
    src = np.array([a.projection_center() for a, _ in pairs])
    tgt = np.array([b.projection_center() for _, b in pairs])
    sim = pycolmap.estimate_sim3d(src, tgt)
    if sim is None:
        return result
    rot = sim.rotation.matrix()
    angles = [rotation_angle_deg(a.cam_from_world().rotation.matrix() @ rot.T,
                                 b.cam_from_world().rotation.matrix()) for a, b in pairs]
    moved = np.array([sim * c for c in src])
    errors = np.linalg.norm(moved - tgt, axis=1)
    return {**result, "median_rotation_error_deg": float(np.median(angles)),
            "max_rotation_error_deg": float(np.max(angles)),
            "median_position_error_mm": 1000 * float(np.median(errors)),
            "p90_position_error_mm": 1000 * float(np.percentile(errors, 90))}


def cloud_view(cloud: dict, camera: Camera, background: int = 255) -> np.ndarray:
    """The points splatted as 3x3 squares coloured by component, far ones first."""
    image = np.full((camera.height, camera.width, 3), background, np.uint8)
    uv, z = project(camera, Lens("PINHOLE"), cloud["xyz"])
    order = np.argsort(-z)
    uv, z, ids = uv[order], z[order], cloud["component"][order]
    col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    keep = (z > camera.znear) & (col >= 1) & (col < camera.width - 1) & (row >= 1) & \
        (row < camera.height - 1)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            image[row[keep] + dy, col[keep] + dx] = COMPONENT_RGB[ids[keep]]
    return image


def flight_sheet(out: Path, env, column: int, frames: int) -> np.ndarray:
    """Three frames (colour, components, damage) over the point cloud within 8 m of the
    column, seen from above the orbit, coloured by component; at half size."""
    rows = []
    for j in np.linspace(0, frames // 2 - 1, 3).round().astype(int):
        folder = out / "frames" / f"frame_{j:04d}"
        color = np.asarray(Image.open(folder / "image.png").convert("RGB"))
        comp = np.asarray(Image.open(folder / "component.png"))
        dmg = np.asarray(Image.open(folder / "damage.png"))
        rows.append(np.concatenate([color, overlay(color, comp, COMPONENT_RGB, 0.55),
                                    overlay(color, dmg, DAMAGE_RGB, 0.8, skip=(1,))], axis=1))
    sheet = np.concatenate(rows, axis=0)
    col = [c for v in env.viaducts for c in v.columns][column]
    h, w = sheet.shape[:2]
    eye = np.array([col.center_xy[0] + 4.0, col.center_xy[1] + 4.0, col.bottom_z + 5.0])
    target = np.array([*col.center_xy, col.bottom_z + 1.5])
    look = target - eye
    pose = look_pose(eye, float(np.arctan2(look[1], look[0])),
                     float(np.arctan2(look[2], np.hypot(look[0], look[1]))))
    camera = Camera(w, h // 2, 24.0, 36.0, pose, 0.1, 500.0)
    cloud = read_ply(out / "points.ply")
    near = np.hypot(*(cloud["xyz"][:, :2] - col.center_xy).T) < 8.0  # the column's surroundings
    cloud = {k: cloud[k][near] for k in ("xyz", "component")}
    full = np.concatenate([sheet, cloud_view(cloud, camera)], axis=0)
    return cv2.resize(full, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--env", type=int, default=0)
    p.add_argument("--column", type=int, default=4)
    p.add_argument("--size", default="960x540")
    p.add_argument("--standoff", type=float, default=2.0)
    p.add_argument("--focal", type=float, default=50.0)
    p.add_argument("--heights", default="1.5,3.0",
                   help="[flight] heights_m: the rings' heights above the column's foot (m)")
    p.add_argument("--overlap", type=int, default=10, help="sequential matching neighbours")
    p.add_argument("--margin", type=float, default=0.5, help="outlier distance [m]")
    p.add_argument("--texture-size", type=int, default=512,
                   help="[materials] texture_size (paper preset: 512), generated at "
                        "max(1024, this)")
    p.add_argument("--concrete-scale", default="0.1,1.0",
                   help="[materials] concrete_scale: repeats per metre (paper preset 0.1,1.0)")
    p.add_argument("--concrete-detail", default="flights", choices=("off", "flights", "on"),
                   help="[materials] concrete_detail (default: flights, i.e. drawn; off: the "
                        "repository's textures alone)")
    p.add_argument("--exposure", default="metered", choices=("metered", "scene"),
                   help="[flight] exposure (default: metered)")
    p.add_argument("--refine-intrinsics", action="store_true",
                   help="let the mapper refine the focal lengths (default: hold the flight's "
                        "exact intrinsics fixed)")
    p.add_argument("--label", default="", help="results file bench_flight_<label>.json")
    p.add_argument("--out", default="/tmp/glsynth-bench-flight")
    args = p.parse_args()
    try:
        import pycolmap
    except ImportError:
        print("bench_flight: pycolmap is not installed (pip install -e .[flights]); nothing "
              "was measured", file=sys.stderr)
        return 0
    root = Path(args.out)
    root.mkdir(parents=True, exist_ok=True)
    out, work = root / "flight", root / "colmap"
    work.mkdir(exist_ok=True)
    t0 = time.perf_counter()
    toml = fly(args, out)
    flown = time.perf_counter() - t0
    summary = json.loads((out / "flight.json").read_text())
    names = [f"frames/frame_{i:04d}/image.png" for i in range(summary["frames"])]
    database = features(pycolmap, out, work, names, args.overlap)
    matched = time.perf_counter() - t0 - flown
    env = build_environment(load_config("paper", toml), args.seed, args.env)
    atomic_write_bytes(RESULTS / "flight" / f"flight{'_' + args.label if args.label else ''}.png",
                       png_bytes(flight_sheet(out, env, args.column, summary["frames"])))
    tri = triangulation(pycolmap, env, out, work, database, args.margin)
    mapper = mapping(pycolmap, out, work, database, summary["frames"], args.refine_intrinsics)
    write_results("bench_flight" + (f"_{args.label}" if args.label else ""), {
        "setting": {k: getattr(args, k) for k in ("seed", "env", "column", "size", "standoff",
                                                   "focal", "heights", "overlap", "margin",
                                                   "texture_size", "concrete_scale",
                                                   "concrete_detail", "exposure",
                                                   "refine_intrinsics")},
        "frames": summary["frames"], "spacing_m": summary["spacing_m"],
        "fly_s": flown, "features_and_matching_s": matched,
        "exposure": summary["exposure"], "matching": match_stats(pycolmap, database),
        "triangulation_with_true_poses": tri, "mapper": mapper})
    return 0


if __name__ == "__main__":
    sys.exit(main())
