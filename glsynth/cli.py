"""The ``glsynth`` command line. Each subcommand parses arguments and calls library functions."""

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from glsynth.config import PRESETS, Config, load_config


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="demo", choices=sorted(PRESETS),
                   help="named configuration (default: demo)")
    p.add_argument("--config", metavar="TOML", help="TOML file overlaid on the preset")


def _add_env_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=_seed, required=True, help="root seed")
    p.add_argument("--env", type=_seed, required=True, help="environment index")


def _seed(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value}: must be an integer >= 0")
    return value


def _config(args: argparse.Namespace) -> Config:
    return load_config(args.preset, args.config)


def cmd_export(args: argparse.Namespace) -> None:
    from glsynth.environment import build_environment
    from glsynth.export import export_environment

    t0 = time.perf_counter()
    env = build_environment(_config(args), args.seed, args.env)
    built = time.perf_counter() - t0
    glb, js = export_environment(env, args.out)
    triangles = sum(len(p.mesh.faces) for p in env.parts)
    print(f"environment {args.env} (seed {args.seed}): {len(env.parts)} parts, {triangles} "
          f"triangles, built in {built:.2f} s -> {glb}, {js}")


def cmd_histograms(args: argparse.Namespace) -> None:
    from glsynth.plots import trajectory_histograms
    from glsynth.seeding import Stream, make_rng
    from glsynth.trajectory import generate_trajectory

    config = _config(args)
    count = args.count or config.dataset.n_environments
    heights, curvatures = [], []
    for env in range(count):
        traj = generate_trajectory(config.environment, config.design.length_m,
                                   make_rng(args.seed, env, Stream.GEOMETRY))
        heights.append(traj.heights_m)
        curvatures.append(traj.curvature)
    h, c = np.concatenate(heights), np.concatenate(curvatures)
    trajectory_histograms(h, c, args.out, f"{count} trajectories x "
                          f"{config.environment.n_viaducts} viaducts (seed {args.seed})")
    straight = np.mean(np.abs(c) < 1 / 5000.0) * 100
    print(f"{h.size} viaducts: height {h.min():.2f}-{h.max():.2f} m, {straight:.1f} % straight "
          f"-> {args.out}")


def cmd_render(args: argparse.Namespace) -> None:
    from glsynth.render import EnvironmentView, describe_output, write_render

    config = _config(args)
    view = EnvironmentView.open(config, args.seed, args.env, renderer=None)
    print(f"GL platform: {view.renderer.platform}")
    for index in args.camera:
        t0 = time.perf_counter()
        placement, output = view.render(index)
        elapsed = time.perf_counter() - t0
        out = Path(args.out) if len(args.camera) == 1 else Path(args.out) / f"camera_{index:03d}"
        write_render(out, placement, output, {"root_seed": args.seed, "env": args.env})
        print(f"camera {index} ({placement.kind}, f = {placement.camera.focal_mm:.1f} mm): "
              f"{describe_output(output)}; rendered in {elapsed:.2f} s -> {out}")


def cmd_preview(args: argparse.Namespace) -> None:
    from glsynth.fileio import atomic_write_bytes, png_bytes
    from glsynth.render import EnvironmentView, preview_config, preview_sheet

    t0 = time.perf_counter()
    config = preview_config(_config(args), args.width)
    view = EnvironmentView.open(config, args.seed, args.env)
    total = config.cameras.n_regular + config.cameras.n_closeup
    cameras = np.linspace(0, total - 1, args.cameras).round().astype(int).tolist()
    atomic_write_bytes(args.out, png_bytes(preview_sheet(view, cameras)))
    print(f"cameras {cameras} at {config.render.width}x{config.render.height} "
          f"(colour | components | damage | depth) in {time.perf_counter() - t0:.1f} s "
          f"-> {args.out}")


def cmd_textures(args: argparse.Namespace) -> None:
    from glsynth.repository import generate_repository

    t0 = time.perf_counter()
    root = generate_repository(args.out, args.seed, args.count, args.size)
    print(f"procedural texture repository ({args.count} per category, {args.size} px) in "
          f"{time.perf_counter() - t0:.1f} s -> {root}")


def cmd_generate(args: argparse.Namespace) -> None:
    from tqdm import tqdm

    from glsynth.dataset import check_format, execute, merge, plan, prepare_output
    from glsynth.fileio import atomic_write_bytes, atomic_write_json, png_bytes
    from glsynth.report import contact_sheet

    config = _config(args)
    check_format(config)
    out = Path(args.out)
    prepare_output(out, config, args.seed)
    tasks = plan(config)
    t0 = time.perf_counter()
    images, timings = 0, {}
    with tqdm(total=len(tasks), unit="unit", desc="glsynth generate") as bar:
        bar.update(sum((out / t.marker).exists() for t in tasks))
        for result in execute(config, args.seed, out, args.workers):
            images += len(result["rows"]) if result["kind"] == "env" else \
                sum(len(v) for v in result["rows"].values())
            for phase, seconds in result["timings"].items():
                timings[phase] = timings.get(phase, 0.0) + seconds
            bar.update(1)
    wall = time.perf_counter() - t0
    summary = merge(config, out)
    summary.update(workers=args.workers, wall_s=round(wall, 2),
                   images_written_this_run=images,
                   images_per_s=round(images / wall, 3) if wall > 0 and images else None,
                   worker_seconds_by_phase={k: round(v, 2) for k, v in timings.items()})
    atomic_write_json(out / "report.json", summary)
    atomic_write_bytes(out / "contact_sheet.png", png_bytes(contact_sheet(out)))
    removed = ", ".join(f"{k} {v}" for k, v in summary["removed"].items())
    dmg = summary["damage_fraction"]
    print(f"kept {summary['kept']} views (removed: {removed}), {summary['plates']} plates; "
          f"concrete damage {100 * dmg['concrete']:.1f} %, exposed rebar "
          f"{100 * dmg['rebar']:.2f} % of damage-task pixels; "
          f"{summary['images_per_s'] or 0:.2f} images/s -> {out}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="glsynth", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("export", help="write one environment as .glb plus scene.json")
    _add_config_args(p)
    _add_env_args(p)
    p.add_argument("--out", required=True, help="output .glb path (scene.json goes beside it)")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("histograms", help="height/curvature histograms (paper Fig. 7) as PNG")
    _add_config_args(p)
    p.add_argument("--seed", type=_seed, required=True, help="root seed")
    p.add_argument("--count", type=int, default=0,
                   help="trajectories (default: the preset's n_environments)")
    p.add_argument("--out", required=True, help="output .png path")
    p.set_defaults(func=cmd_histograms)

    p = sub.add_parser("render", help="render cameras of one environment at full resolution")
    _add_config_args(p)
    _add_env_args(p)
    p.add_argument("--camera", type=_seed, nargs="+", required=True,
                   help="camera index: the [cameras] n_regular regular ones first, then the "
                        "close-ups (paper preset: 0-49, 50-99); several make subfolders")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("preview", help="low-resolution contact sheet of one environment")
    _add_config_args(p)
    _add_env_args(p)
    p.add_argument("--cameras", type=int, default=6, help="how many cameras (spread evenly)")
    p.add_argument("--width", type=int, default=384, help="width of each tile in pixels")
    p.add_argument("--out", required=True, help="output .png")
    p.set_defaults(func=cmd_preview)

    p = sub.add_parser("generate", help="render a dataset in the released Tokaido layout")
    _add_config_args(p)
    p.add_argument("--seed", type=_seed, required=True, help="root seed")
    p.add_argument("--out", required=True, help="dataset folder (new, or a run to resume)")
    p.add_argument("--workers", type=int, default=1, help="local processes, one GL context each")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("textures", help="generate a procedural texture repository folder")
    p.add_argument("--out", required=True, help="repository folder (one sub-folder a category)")
    p.add_argument("--seed", type=_seed, default=0)
    p.add_argument("--count", type=int, default=12, help="images per category")
    p.add_argument("--size", type=int, default=512, help="image size in pixels")
    p.set_defaults(func=cmd_textures)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ValueError, TypeError, OSError) as err:
        print(f"glsynth {args.command}: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
