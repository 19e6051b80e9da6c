"""COLMAP on a glsynth flight: do the textures carry enough detail for multi-view work?

Flies an orbit with `glsynth fly`, then runs COLMAP itself (pycolmap, the [flights] extra) on
its colour images alone (glsynth.measure.colmap_check): SIFT features, sequential matching of
each frame with the next `--overlap`, the point triangulator with the exact poses (distances
of the points to the true surfaces; beyond --margin counts as an outlier), and the mapper
from scratch (registered share, pose errors after a similarity alignment).

    .venv/bin/python bench/bench_flight.py [--size 960x540] [--standoff 2] [--focal 50]
                                           [--heights 1.5,3.0]
                                           [--overlap 10] [--texture-size 512]
                                           [--concrete-scale 0.1,1.0] [--label L]
                                           [--concrete-detail flights|off]
                                           [--exposure metered|scene] [--refine-intrinsics]
                                           [--world panels|town]
                                           [--out /tmp/glsynth-bench-flight]

It also draws bench/results/flight/flight.png: three frames with their labels, and the point
cloud seen from outside the orbit, coloured by component. The issue's setting, a 5 m orbit,
is refused: from 4.5 m the ring comes within the 1 m clearance of the next column along the
track (columns stand 6 m apart both ways); 4 m (100 frames at 80 % overlap) is the widest.
Skips, saying so, where pycolmap is not installed.
"""

import argparse
import json
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
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, overlay  # noqa: E402
from glsynth.data.flight_export import project, read_ply  # noqa: E402
from glsynth.measure import colmap_check  # noqa: E402
from glsynth.world.cameras import Camera  # noqa: E402
from glsynth.world.environment import build_environment  # noqa: E402
from glsynth.world.flights import look_pose  # noqa: E402
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
                    f"exposure = \"{args.exposure}\"\n"
                    f"[environment]\nworld = \"{args.world}\"\n")
    code = glsynth(["fly", "--preset", "paper", "--seed", str(args.seed), "--env",
                    str(args.env), "--config", str(toml), "--out", str(out)])
    if code:
        raise SystemExit(f"glsynth fly failed ({code})")
    return toml


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
    p.add_argument("--world", default="panels", choices=("panels", "town"),
                   help="[environment] world (default: panels, the paper preset's; the "
                        "README's picture: town)")
    p.add_argument("--refine-intrinsics", action="store_true",
                   help="let the mapper refine the focal lengths (default: hold the flight's "
                        "exact intrinsics fixed)")
    p.add_argument("--label", default="", help="results file bench_flight_<label>.json")
    p.add_argument("--out", default="/tmp/glsynth-bench-flight")
    args = p.parse_args()
    if colmap_check.pycolmap is None:
        print("bench_flight: pycolmap is not installed (pip install -e .[flights]); nothing "
              "was measured", file=sys.stderr)
        return 0
    root = Path(args.out)
    root.mkdir(parents=True, exist_ok=True)
    out, work = root / "flight", root / "colmap"
    t0 = time.perf_counter()
    toml = fly(args, out)
    flown = time.perf_counter() - t0
    summary = json.loads((out / "flight.json").read_text())
    env = build_environment(load_config("paper", toml), args.seed, args.env)
    atomic_write_bytes(RESULTS / "flight" / f"flight{'_' + args.label if args.label else ''}.png",
                       png_bytes(flight_sheet(out, env, args.column, summary["frames"])))
    checked = colmap_check.reconstruct(env, out, work, args.overlap, args.margin,
                                       args.refine_intrinsics)
    checked_s = time.perf_counter() - t0 - flown
    write_results("bench_flight" + (f"_{args.label}" if args.label else ""), {
        "setting": {k: getattr(args, k) for k in ("seed", "env", "column", "size", "standoff",
                                                   "focal", "heights", "overlap", "margin",
                                                   "texture_size", "concrete_scale",
                                                   "concrete_detail", "exposure", "world",
                                                   "refine_intrinsics")},
        "frames": summary["frames"], "spacing_m": summary["spacing_m"],
        "fly_s": flown, "colmap_s": checked_s, "exposure": summary["exposure"], **checked})
    return 0


if __name__ == "__main__":
    sys.exit(main())
