"""The ``glsynth`` command line. Each subcommand parses arguments and calls library functions."""

import argparse
import dataclasses
import functools
import logging
import math
import sys
import time
import typing
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from glsynth.assess.condition import AssessSettings
from glsynth.core.config import (
    PRESETS,
    TEXTURE_PX,
    Config,
    FlightConfig,
    RenderConfig,
    config_from_dict,
    load_config,
)
from glsynth.core.errors import UserError, clipped
from glsynth.core.interrupts import held_interrupt
from glsynth.core.options import (
    add_options,
    argparse_type,
    field_choices,
    from_options,
    parse_size,
)
from glsynth.data.engines import ENGINES
from glsynth.data.quality import QUALITY, apply_quality
from glsynth.model.settings import TrainSettings

# Each command has an add_<command>_parser, which declares its options, and a cmd_<command>,
# which runs it. An option that several commands take is declared once, in an _add_*_arg(s)
# function below.


MAX_INT = 2**63 - 1
"""The largest seed, index or count an option takes: numpy's seeds and indices are 64-bit."""


def _bounded_int(text: str, low: int) -> int:
    """An integer option in [low, MAX_INT]; the refusal quotes at most 30 characters of it."""
    value = int(text)
    if not low <= value <= MAX_INT:
        quoted = text if len(text) <= 30 else f"{text[:27]}..."
        raise argparse.ArgumentTypeError(f"{quoted}: must be an integer in [{low}, 2**63 - 1]")
    return value


def non_negative_int(text: str) -> int:
    """Seeds, indices and counts that may be zero, up to MAX_INT."""
    return _bounded_int(text, 0)


def positive_int(text: str) -> int:
    return _bounded_int(text, 1)


def positive_int_list(text: str) -> list[int]:
    """'1,16,64' -> [1, 16, 64], each an integer >= 1."""
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give integers >= 1, comma-separated "
                                         "(e.g. 1,16,64)")
    return values


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="demo", choices=sorted(PRESETS),
                   help="named configuration (default: demo)")
    p.add_argument("--config", metavar="TOML", help="TOML file overlaid on the preset")


def _add_quality_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quality", choices=list(QUALITY), default=None,
                   help="quality preset overriding resolution, MSAA, textures, octaves, "
                        "tessellation (README: Quality presets)")


def _add_renderer_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--renderer", choices=field_choices(RenderConfig, "renderer"), default=None,
                   help="colour by the GL rasterizer or by Blender Cycles (labels and depth "
                        "always by GL; default: [render] renderer)")
    p.add_argument("--samples", type=positive_int, default=None,
                   help="Cycles samples per pixel (default: [cycles] samples)")


def _add_seed_arg(p: argparse.ArgumentParser, required: bool = True) -> None:
    """``--seed``, required by the commands that make data, 0 by default in the benches."""
    p.add_argument("--seed", type=non_negative_int, required=required,
                   default=None if required else 0, help="root seed")


def _add_env_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    _add_seed_arg(p, required)
    p.add_argument("--env", type=non_negative_int, required=required,
                   default=None if required else 0, help="environment index")


def _add_cameras_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cameras", type=positive_int, default=6,
                   help="how many cameras, spread evenly over the environment (default 6)")


def _add_blender_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--blender", default=None, help="Blender executable (default: PATH)")


def _add_run_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--run", required=True, help="folder of a trained run (glsynth train --out)")


def _add_split_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--split", choices=("train", "test"), default="test")


def _add_device_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", default="auto", help="auto, cpu, cuda or cuda:N (default: auto)")


MAX_PREVIEW_CAMERAS = 64
"""A contact sheet of 64 rows at 384 px is 64 x 216 px high: beyond it a sheet is no preview."""
MAX_PREVIEW_WIDTH = 3840
MAX_TRAJECTORIES = 100_000
"""histograms --count: far above any preset's n_environments, far below a hang."""
MAX_TEXTURES_PER_CATEGORY = 10_000
"""textures --count: as many as [materials] images_per_category may use."""


def _at_most(option: str, value: int, limit: int, what: str) -> None:
    """Refuse, before any work, a user-sized loop beyond its bound, naming the bound."""
    if value > limit:
        raise UserError(f"{option} {value:,}: {what} at most {limit:,}; give a smaller "
                        f"{option}")


def _check_cameras(config: Config, indices: list[int]) -> None:
    """Before any work: every camera index exists in this config."""
    n = config.cameras.total
    bad = [i for i in indices if i >= n]
    if bad:
        raise UserError(f"--camera {bad[0]}: this config has cameras 0 to {n - 1} "
                        f"({config.cameras.n_regular} regular, then {config.cameras.n_closeup} "
                        "close-ups)")


def _config(args: argparse.Namespace) -> Config:
    config = load_config(args.preset, args.config)
    if getattr(args, "quality", None):
        config = apply_quality(config, args.quality)
    # Only commands with the renderer options (render, generate) override the config with them.
    if hasattr(args, "renderer"):
        given = {"render": {"renderer": args.renderer}, "cycles": {"samples": args.samples}}
        config = config_from_dict({section: {k: v for k, v in values.items() if v is not None}
                                   for section, values in given.items()}, config)
    if config.render.renderer == "cycles":
        from glsynth.render.cycles import require_blender

        require_blender(getattr(args, "blender", None), option=hasattr(args, "blender"),
                        instead="--renderer gl" if hasattr(args, "renderer")
                        else '[render] renderer = "gl" in --config')
    return config


Commands = argparse._SubParsersAction
"""What ``add_subparsers`` returns: each add_<command>_parser adds its command to it."""


def add_export_parser(sub: Commands) -> None:
    p = sub.add_parser("export", help="write one environment as .glb plus scene.json")
    _add_config_args(p)
    _add_env_args(p)
    p.add_argument("--out", required=True, help="output .glb path (scene.json goes beside it)")
    p.add_argument("--flat", action="store_true",
                   help="flat colours per component, no textures or light (small files)")
    _add_quality_arg(p)
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> None:
    from glsynth.appearance.damage_bank import DamageBank
    from glsynth.appearance.dressing import dress, open_repository
    from glsynth.render.export import export_environment, glb_path
    from glsynth.world.environment import build_environment
    from glsynth.world.lighting import environment_lighting

    glb_path(args.out)  # a wrong path is refused before the environment is built
    t0 = time.perf_counter()
    config = _config(args)
    env = build_environment(config, args.seed, args.env)
    materials = None
    if not args.flat:  # every column that may be damaged gets its damage textures
        materials = dress(env, config, open_repository(config),
                          DamageBank(config.damage, args.seed),
                          {p.name for p in env.parts}).materials
    built = time.perf_counter() - t0
    light = environment_lighting(config.lighting, args.seed, args.env)
    glb, js = export_environment(env, args.out, materials, None if args.flat else light)
    triangles = sum(len(p.mesh.faces) for p in env.parts)
    print(f"environment {args.env} (seed {args.seed}): {len(env.parts)} parts, {triangles} "
          f"triangles, built in {built:.2f} s -> {glb}, {js}")


def add_histograms_parser(sub: Commands) -> None:
    p = sub.add_parser("histograms", help="height/curvature histograms (paper Fig. 7) as PNG")
    _add_config_args(p)
    _add_seed_arg(p)
    p.add_argument("--count", type=non_negative_int, default=0,
                   help="trajectories (default: the preset's n_environments)")
    p.add_argument("--out", required=True, help="output .png path")
    p.set_defaults(func=cmd_histograms)


def cmd_histograms(args: argparse.Namespace) -> None:
    from glsynth.core.plots import trajectory_histograms
    from glsynth.core.seeding import Stream, make_rng
    from glsynth.world.trajectory import generate_trajectory

    config = _config(args)
    count = args.count or config.dataset.n_environments
    _at_most("--count", count, MAX_TRAJECTORIES, "the histograms sum")
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


def add_render_parser(sub: Commands) -> None:
    p = sub.add_parser("render", help="render cameras of one environment at full resolution")
    _add_config_args(p)
    _add_env_args(p)
    _add_quality_arg(p)
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--camera", type=non_negative_int, nargs="+",
                       help="camera index: the [cameras] n_regular regular ones first, then "
                            "the close-ups (paper preset: 0-49, 50-99); several make "
                            "subfolders")
    which.add_argument("--camera-json", metavar="FILE",
                       help="a camera placed by hand: JSON with pose (4x4 world-from-camera) "
                            "and focal_mm, as glsynth view's 'copy camera' or a camera.json")
    _add_renderer_args(p)
    _add_blender_arg(p)
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=cmd_render)


def cmd_render(args: argparse.Namespace) -> None:
    from glsynth.core.runlock import RunLock

    config = _config(args)
    if args.camera_json:
        return _render_camera_json(args, config)
    _check_cameras(config, args.camera)
    with RunLock(args.out):
        _render_cameras(args, config)


def _render_cameras(args: argparse.Namespace, config: Config) -> None:
    """render --camera: the cameras of one environment, while this process holds --out."""
    from glsynth.render.view import EnvironmentView, describe_output, write_render

    # Only the parts the asked cameras see (or that shadow them) are dressed and uploaded.
    view = EnvironmentView.open(config, args.seed, args.env, renderer=None,
                                rendering=args.camera)
    print(f"GL platform: {view.renderer.platform}")
    rendered = []
    for index in args.camera:
        t0 = time.perf_counter()
        # Cycles replaces the colour below, unphotographed: the GL colour is not photographed.
        placement, output = view.render(index, photo=config.render.renderer == "gl")
        rendered.append((placement, output, time.perf_counter() - t0))
    if config.render.renderer == "cycles":
        from glsynth.render.cycles import cycles_colour

        t0 = time.perf_counter()
        colours = cycles_colour(view, [p for p, _, _ in rendered], Path(args.out) / ".cycles",
                                args.blender)
        each = (time.perf_counter() - t0) / len(rendered)
        rendered = [(p, dataclasses.replace(o, color=c), t + each)
                    for (p, o, t), c in zip(rendered, colours)]
    for placement, output, elapsed in rendered:
        index = placement.index
        out = Path(args.out) if len(args.camera) == 1 else Path(args.out) / f"camera_{index:03d}"
        write_render(out, placement, output, {"root_seed": args.seed, "env": args.env,
                                              "renderer": config.render.renderer})
        print(f"camera {index} ({placement.kind}, f = {placement.camera.focal_mm:.1f} mm): "
              f"{describe_output(output)}; rendered in {elapsed:.2f} s -> {out}")


def _render_camera_json(args: argparse.Namespace, config: Config) -> None:
    """render --camera-json: one camera placed anywhere, so every part is uploaded and every
    column damaged (EnvironmentView.open's ``anywhere``); colour by GL."""
    from glsynth.core.runlock import RunLock
    from glsynth.render.view import EnvironmentView, describe_output, write_render
    from glsynth.view.camera import read_camera_json

    if config.render.renderer == "cycles":
        raise UserError("--camera-json renders with GL only; drop --renderer cycles")
    camera = read_camera_json(args.camera_json, config)
    with RunLock(args.out):
        view = EnvironmentView.open(config, args.seed, args.env, cull=False, anywhere=True)
        t0 = time.perf_counter()
        output = view.photograph(view.renderer.render(camera), camera, 0)
        elapsed = time.perf_counter() - t0
        write_render(args.out, camera, output, {"root_seed": args.seed, "env": args.env,
                                                "renderer": "gl"})
    print(f"camera {args.camera_json} (f = {camera.focal_mm:.1f} mm): "
          f"{describe_output(output)}; rendered in {elapsed:.2f} s -> {args.out}")


def add_preview_parser(sub: Commands) -> None:
    p = sub.add_parser("preview", help="low-resolution contact sheet of one environment")
    _add_config_args(p)
    _add_env_args(p)
    _add_cameras_arg(p)
    p.add_argument("--width", type=positive_int, default=384,
                   help="width of each tile in pixels")
    p.add_argument("--out", required=True, help="output .png")
    p.set_defaults(func=cmd_preview)


def cmd_preview(args: argparse.Namespace) -> None:
    from glsynth.core.fileio import atomic_write_bytes, png_bytes
    from glsynth.render.view import EnvironmentView, preview_config, preview_sheet

    _at_most("--cameras", args.cameras, MAX_PREVIEW_CAMERAS, "a preview sheet shows")
    _at_most("--width", args.width, MAX_PREVIEW_WIDTH, "a preview tile is wide")
    t0 = time.perf_counter()
    config = preview_config(_config(args), args.width)
    if args.cameras > config.cameras.total:
        raise UserError(f"--cameras {args.cameras}: this config has {config.cameras.total} "
                        f"cameras per environment; give at most {config.cameras.total}")
    view = EnvironmentView.open(config, args.seed, args.env)
    cameras = np.linspace(0, config.cameras.total - 1, args.cameras).round().astype(int).tolist()
    atomic_write_bytes(args.out, png_bytes(preview_sheet(view, cameras)))
    print(f"cameras {cameras} at {config.render.width}x{config.render.height} "
          f"(colour | components | damage | depth) in {time.perf_counter() - t0:.1f} s "
          f"-> {args.out}")


def port_number(text: str) -> int:
    value = int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{value}: a port is 0 to 65535 (0: any free one)")
    return value


def add_view_parser(sub: Commands) -> None:
    p = sub.add_parser("view", help="interactive preview in the browser: free camera, passes, "
                                    "sampled cameras, lighting, inspect, save")
    _add_config_args(p)
    _add_env_args(p, required=False)
    _add_quality_arg(p)
    p.add_argument("--port", type=port_number, default=8080, help="default 8080")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1, this machine only); another "
                        "lets anyone who reaches it render and save views (README)")
    p.add_argument("--out", default="views",
                   help="folder 'save view' writes view_NNN folders into (default ./views)")
    # A preview: 'fast' holds 10 frames/s while moving on 2 CPU cores (docs/results.md).
    p.set_defaults(func=cmd_view, quality="fast")


def cmd_view(args: argparse.Namespace) -> int:
    # Ctrl-C is held until the server takes the signals over (glsynth.core.interrupts says
    # why): the imports below and the server's start are not safe for it.
    try:
        with held_interrupt() as noted:
            _serve_view(args, noted)
    except KeyboardInterrupt:
        print("glsynth view: stopped", file=sys.stderr)
        return 130
    return 0


def _serve_view(args: argparse.Namespace, noted: list[int]) -> None:
    from glsynth.core.reading import MAX_TOML_BYTES, read_bytes
    from glsynth.core.runlock import RunLock
    from glsynth.view.scene import SceneSettings, scene_config
    from glsynth.view.server import serve

    load_config(args.preset, args.config)  # its errors name the file
    text = read_bytes(Path(args.config), "config file", MAX_TOML_BYTES, "give a .toml file"
                      ).decode("utf-8") if args.config else None
    settings = SceneSettings(args.preset, args.seed, args.env, args.quality, text)
    scene_config(settings)

    def ready(url: str) -> None:
        if args.host not in ("127.0.0.1", "localhost", "::1"):
            print(f"glsynth view: listening on {args.host}: anyone who reaches it can render "
                  f"and save views into {args.out}", file=sys.stderr)
        print(f"glsynth view: open {url} (Ctrl-C stops)", flush=True)

    # 'save view' writes into --out: it is checked and held as generate's and fly's are,
    # before the port is bound.
    with RunLock(args.out):
        serve(settings, args.host, args.port, Path(args.out), ready, noted)


def add_generate_parser(sub: Commands) -> None:
    p = sub.add_parser("generate", help="render a dataset in the released Tokaido layout")
    _add_config_args(p)
    _add_quality_arg(p)
    _add_renderer_args(p)
    _add_seed_arg(p)
    p.add_argument("--out", required=True, help="dataset folder (new, or a run to resume)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="worker processes (local) or Ray actors, one GL context each")
    p.add_argument("--engine", choices=ENGINES, default="local",
                   help="local processes, or Ray actors sharded by environment")
    p.add_argument("--address", default=None,
                   help="Ray cluster address ('auto', 'host:6379', 'ray://host:10001'); "
                        "default starts a local Ray. --out must be shared by all nodes")
    p.set_defaults(func=cmd_generate)


def cmd_generate(args: argparse.Namespace) -> None:
    from glsynth.core.runlock import RunLock
    from glsynth.data.dataset import check_format
    from glsynth.data.engines import check_engine

    config = _config(args)
    check_format(config)
    check_engine(args.engine, args.workers, args.address)
    out = Path(args.out)
    with RunLock(out):
        _generate(args, config, out)


def _generate(args: argparse.Namespace, config: Config, out: Path) -> None:
    """The run itself, while this process holds the output folder's lock."""
    from tqdm import tqdm

    from glsynth.core.fileio import atomic_write_bytes, atomic_write_json, png_bytes
    from glsynth.data.dataset import merge, plan, prepare_output
    from glsynth.data.engines import execute
    from glsynth.data.readers import is_marker
    from glsynth.data.report import (
        contact_sheet,
        recorded_runs,
        run_record,
        tally_results,
        with_runs,
    )

    prepare_output(out, config, args.seed)
    earlier = recorded_runs(out / "report.json")  # refused before any work if unreadable
    tasks = plan(config)
    t0 = time.perf_counter()
    results = execute(config, args.seed, out, args.workers, args.engine, args.address)
    with tqdm(results, total=len(tasks), initial=sum(is_marker(out / t.marker) for t in tasks),
              unit="unit", desc="glsynth generate") as bar:
        tally = tally_results(bar)
    run = run_record(tally, args.engine, args.workers, time.perf_counter() - t0)
    report = with_runs(merge(config, out), earlier, run)
    atomic_write_json(out / "report.json", report)
    atomic_write_bytes(out / "contact_sheet.png", png_bytes(contact_sheet(out)))
    print(_generated(report, out))


def _generated(report: dict, out: Path) -> str:
    """The line that sums up a finished generate run."""
    stats = report["statistics"]
    keep = ", ".join(f"{k} {100 * v:.1f} %" for k, v in stats["keep_rate"].items()
                     if v is not None)
    dmg = stats["damage_share"]
    return (f"kept {report['kept']} views (keep rate {keep}), {report['plates']} plates; "
            f"concrete damage {100 * (dmg['concrete'] or 0):.1f} %, exposed rebar "
            f"{100 * (dmg['rebar'] or 0):.2f} % of damage-task pixels; "
            f"{report['images_per_s'] or 0:.2f} images/s -> {out} (glsynth stats {out} for "
            "the table beside the paper's)")


def add_fly_parser(sub: Commands) -> None:
    p = sub.add_parser("fly", help="render an inspection flight ([flight]) with COLMAP, "
                                   "nerfstudio and point-cloud exports")
    _add_config_args(p)
    _add_env_args(p)
    p.add_argument("--plan", choices=field_choices(FlightConfig, "plan"), default=None,
                   help="flight plan (default: [flight] plan)")
    p.add_argument("--out", required=True, help="flight folder (new, or a flight to resume)")
    p.set_defaults(func=cmd_fly)


def cmd_fly(args: argparse.Namespace) -> None:
    from glsynth.core.runlock import RunLock, check_out

    config = _config(args)
    if args.plan:
        config = config_from_dict({"flight": {"plan": args.plan}}, config)
    check_out(args.out)  # at once, not after the environment is built
    from glsynth.data.flight import check_flight, run_flight  # trimesh and the GL: 0.5 s

    checked = check_flight(config, args.seed, args.env)  # before --out is made or locked
    with RunLock(args.out):
        done = run_flight(config, args.seed, args.env, Path(args.out), checked)
    each = f", {done['render_s_per_frame']:.2f} s each" if done["rendered"] else ""
    print(f"{done['plan']}: {done['frames']} frames {done['spacing_m']:.2f} m apart "
          f"({done['rendered']} rendered now{each}), {done['parts_built']} of {done['parts']} "
          f"parts built, opened in {done['open_s']:.2f} s; {done['points']} points -> "
          f"{args.out}")


def add_stats_parser(sub: Commands) -> None:
    p = sub.add_parser("stats", help="a dataset's statistics beside the paper's (glsynth's or "
                                     "the released Tokaido dataset)")
    p.add_argument("dataset", help="Tokaido-layout dataset root")
    p.add_argument("--out", required=True, help="folder for stats.json, stats.md, stats.png")
    p.set_defaults(func=cmd_stats)


def cmd_stats(args: argparse.Namespace) -> None:
    from glsynth.data.statistics import statistics_table, write_statistics

    out = Path(args.out)
    stats = write_statistics(args.dataset, out)
    print(statistics_table(stats), end="")
    print(f"-> {out}/stats.json, stats.md, stats.png")


def add_train_parser(sub: Commands) -> None:
    p = sub.add_parser("train", help="train FCN58 on a Tokaido-layout dataset (needs torch)")
    add_options(p, TrainSettings)
    p.add_argument("--out", required=True, help="run folder (new, or a run to resume)")
    p.set_defaults(func=cmd_train)


def cmd_train(args: argparse.Namespace) -> None:
    from glsynth.model.train import train

    settings = from_options(TrainSettings, args)
    last = train(settings, args.out)
    print(f"trained {args.task} for {last.get('epoch', 0)} epochs -> {args.out}/model.pt")


def add_evaluate_parser(sub: Commands) -> None:
    p = sub.add_parser("evaluate", help="metrics of a trained run on a dataset split")
    _add_run_arg(p)
    p.add_argument("--data", required=True, help="Tokaido-layout dataset root")
    _add_split_arg(p)
    p.add_argument("--out", default=None, help="default: RUN/eval_<split>")
    p.add_argument("--examples", type=non_negative_int, default=6,
                   help="example overlays to write")
    p.add_argument("--no-puretex", action="store_true", help="damage: leave out the plates")
    _add_device_arg(p)
    p.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args: argparse.Namespace) -> None:
    from glsynth.model.inference import evaluate

    out = args.out or str(Path(args.run) / f"eval_{args.split}")
    m = evaluate(args.run, args.data, args.split, out, args.examples,
                 puretex=not args.no_puretex, device=args.device)
    if m["task"] == "depth":
        d = m["depth"]
        print(f"depth on {m['images']} {args.split} images: MAE {d['mae_m']:.3f} m, RMSE "
              f"{d['rmse_m']:.3f} m, ARD {100 * d['ard']:.2f} % -> {out}")
    else:
        scores = ", ".join(f"{k} {100 * v['iou']:.1f}" for k, v in m["per_class"].items()
                           if v["iou"] is not None)
        print(f"{m['task']} on {m['images']} {args.split} images: mean IoU "
              f"{100 * (m['mean']['iou'] or 0):.1f} % ({scores}) -> {out}")


def add_predict_parser(sub: Commands) -> None:
    p = sub.add_parser("predict", help="run a trained network on photos")
    _add_run_arg(p)
    p.add_argument("images", nargs="+")
    p.add_argument("--out", required=True)
    _add_device_arg(p)
    p.set_defaults(func=cmd_predict)


def cmd_predict(args: argparse.Namespace) -> None:
    from glsynth.model.inference import predict_files

    written = predict_files(args.run, args.images, args.out, args.device)
    print(f"{len(written)} predictions -> {args.out}")


def add_assess_parser(sub: Commands) -> None:
    p = sub.add_parser("assess", help="condition assessment: damage x RRDR x component")
    p.add_argument("images", nargs="*", help="photos to assess (with --runs)")
    p.add_argument("--runs", default=None, metavar="component=R1,damage=R2,depth=R3")
    p.add_argument("--oracle", default=None, metavar="DATA",
                   help="use ground-truth maps instead of networks: a dataset's split, or a "
                        "glsynth render output (its maps at the image's full size)")
    p.add_argument("--data", default=None,
                   help="with --runs: assess a labelled split and evaluate before/after RRDR")
    _add_split_arg(p)
    p.add_argument("--limit", type=positive_int, default=None,
                   help="at most this many dataset images")
    p.add_argument("--focal-mm", type=float, default=None,
                   help="focal length of the photos; unknown: RRDR from the depth range")
    p.add_argument("--ignore-focal", action="store_true",
                   help="with --data: RRDR from the depth range, as the paper's Table 13")
    p.add_argument("--sensor-mm", type=float, default=36.0, help="sensor width [mm]")
    add_options(p, AssessSettings)
    _add_device_arg(p)
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_assess)


def cmd_assess(args: argparse.Namespace) -> int:
    from glsynth.assess.condition import (
        assess_photos,
        oracle_photos,
        render_folders,
        render_photos,
    )
    from glsynth.core.runlock import RunLock

    settings = from_options(AssessSettings, args)
    out = Path(args.out)
    for name, value in (("--sensor-mm", args.sensor_mm), ("--focal-mm", args.focal_mm)):
        if value is not None and not 0 < value < math.inf:
            raise UserError(f"{name} {value}: give a length in millimetres > 0 (a full-frame "
                            "sensor is 36 mm wide)")
    if (args.runs is None) == (args.oracle is None):
        raise UserError("give either --runs component=R1,damage=R2,depth=R3 or --oracle DATA")
    if args.oracle is not None:
        if args.images:
            raise UserError("--oracle takes its images from the dataset; drop IMAGES")
        renders = render_folders(Path(args.oracle))
        photos = (render_photos(renders, args.limit) if renders else
                  oracle_photos(Path(args.oracle), args.split, args.sensor_mm, args.limit))
    with RunLock(out):
        if args.oracle is None:
            photos = _network_photos(args, settings, out)
        summary = assess_photos(photos, out, settings)
    for failure in summary["failed"]:
        print(clipped(f"glsynth assess: {failure['image']}: {failure['error']}"),
              file=sys.stderr)
    print(f"assessed {len(summary['assessed'])} images, {len(summary['failed'])} failed -> "
          f"{out}")
    return 1 if summary["failed"] else 0


def _network_photos(args: argparse.Namespace, settings: AssessSettings, out: Path) -> list:
    """assess --runs: the networks' maps of IMAGES, or of a labelled split (--data), which is
    also evaluated before and after RRDR."""
    from glsynth.model.pipeline import evaluate_rrdr, load_predictors, network_photos, parse_runs

    if bool(args.images) == bool(args.data):
        raise UserError("with --runs give IMAGES to assess, or --data DIR to assess and "
                        "evaluate a labelled split")
    predictors = load_predictors(parse_runs(args.runs), args.device)
    images, focals = list(args.images), [args.focal_mm] * len(args.images)
    if args.data:
        from glsynth.data.tokaido import read_manifest

        result = evaluate_rrdr(predictors, Path(args.data), out / "evaluation", settings,
                               args.split, use_focal=not args.ignore_focal,
                               sensor_mm=args.sensor_mm)
        _print_rrdr_scores(result)
        rows = read_manifest(Path(args.data), f"files_{args.split}.csv")[:args.limit]
        images = [str(Path(args.data) / r.image) for r in rows]
        focals = [None if args.ignore_focal else r.focal_mm for r in rows]
    return network_photos(predictors, images, focals, args.sensor_mm)


def _print_rrdr_scores(result: dict) -> None:
    """Damage precision, recall and IoU before and after RRDR masking."""
    b, a = result["before"]["per_class"], result["after"]["per_class"]
    for name in ("concrete", "rebar"):
        print(f"{name}: " + "; ".join(
            f"{when} P/R/IoU " + "/".join(
                "-" if s[k] is None else f"{100 * s[k]:.1f}"
                for k in ("precision", "recall", "iou"))
            for when, s in (("before", b[name]), ("after RRDR", a[name]))))


def add_bench_parser(sub: Commands) -> None:
    p = sub.add_parser("bench", help="measurements: 'quality' (speed against accuracy), "
                                     "'blender' (against Cycles, if Blender is installed), "
                                     "'sim2real' (glsynth-trained cracks on real photographs)")
    bench = p.add_subparsers(dest="bench", required=True)
    add_bench_quality_parser(bench)
    add_bench_blender_parser(bench)
    add_bench_sim2real_parser(bench)


def _add_sample_counts_arg(p: argparse.ArgumentParser, default: list[int], use: str) -> None:
    p.add_argument("--samples", type=positive_int_list, default=default,
                   help=f"Cycles sample counts {use}, comma-separated (default "
                        f"{','.join(map(str, default))})")


def add_bench_quality_parser(sub: Commands) -> None:
    p = sub.add_parser("quality", help="render fixed views under each quality preset")
    _add_config_args(p)
    _add_env_args(p, required=False)
    _add_cameras_arg(p)
    p.add_argument("--presets", default=None, help="comma-separated (default: all)")
    p.add_argument("--reference", choices=("cycles", "glsynth"), default="cycles",
                   help="colour reference: Blender Cycles (needs Blender) or glsynth's "
                        "'reference' preset")
    p.add_argument("--reference-samples", type=positive_int, default=128)
    _add_sample_counts_arg(p, [1, 4, 16, 64], "for the time axis")
    # SSIM compares 7x7 windows: 16 px a side leaves it room.
    p.add_argument("--size", type=argparse_type(functools.partial(parse_size, minimum=16),
                                                "--size"),
                   default=(480, 270), metavar="WxH",
                   help="size at which colour is compared (default 480x270)")
    _add_blender_arg(p)
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_bench_quality)


def cmd_bench_quality(args: argparse.Namespace) -> None:
    from glsynth.measure.quality_bench import bench_quality, quality_table, spread_cameras
    from glsynth.render.cycles import require_blender

    presets = args.presets.split(",") if args.presets else list(QUALITY)
    unknown = set(presets) - set(QUALITY)
    if unknown:
        raise UserError(f"--presets: unknown {sorted(unknown)}; choose from {list(QUALITY)}")
    config = load_config(args.preset, args.config)
    _at_most("--cameras", args.cameras, config.cameras.total, "an environment of this config "
             "has")
    blender = None if args.reference == "glsynth" else \
        require_blender(args.blender, option=True, instead="--reference glsynth")
    cameras = spread_cameras(config.cameras.total, args.cameras)
    result = bench_quality(config, args.seed, args.env, cameras, Path(args.out), presets,
                           blender, args.size, args.reference_samples, tuple(args.samples))
    print(quality_table(result), end="")
    print(f"-> {args.out}/quality.md, quality.png, quality.json")


def add_bench_blender_parser(sub: Commands) -> None:
    p = sub.add_parser("blender", help="one camera in Blender Cycles against glsynth: time, "
                                       "component labels, depth (optional)")
    _add_config_args(p)
    _add_quality_arg(p)
    _add_env_args(p, required=False)
    p.add_argument("--camera", type=non_negative_int, default=0,
                   help="camera index in the environment")
    _add_sample_counts_arg(p, [1, 16], "of the colour renders")
    _add_blender_arg(p)
    p.add_argument("--timeout-min", type=float, default=30.0)
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_bench_blender)


def cmd_bench_blender(args: argparse.Namespace) -> int:
    from glsynth.measure.blender_bench import bench_blender, blender_table
    from glsynth.render.cycles import find_blender

    blender = find_blender(args.blender)
    if blender is None:
        print("glsynth bench blender: Blender is not installed, so nothing was measured. "
              "Install the Debian package `blender` (apt-get install blender) or pass "
              "--blender PATH; this bench is optional.", file=sys.stderr)
        return 0
    config = _config(args)
    _check_cameras(config, [args.camera])
    result = bench_blender(config, args.seed, args.env, args.camera, args.samples,
                           Path(args.out), blender, args.timeout_min * 60)
    print(blender_table(result), end="")
    print(f"-> {args.out}/blender.md, blender.json, blender_*spp.png")
    return 0


def add_bench_sim2real_parser(sub: Commands) -> None:
    p = sub.add_parser("sim2real", help="train a small crack segmenter on glsynth renders and "
                                        "on real photographs; score all on real ones (needs "
                                        "torch)")
    p.add_argument("--synthetic", required=True, nargs="+",
                   help="glsynth datasets (Tokaido layout, with crack-width maps: --preset "
                        "inspection), one network each")
    p.add_argument("--real", required=True,
                   help="folder of real photographs: images/ and masks/ (same file names; "
                        "crack pixels > 0 in a 0/1 mask, > 127 in a 0/255 or JPEG one)")
    p.add_argument("--other-real", nargs="+", default=[], metavar="FOLDER",
                   help="folders of real photographs of another kind (images/ and masks/), "
                        "one network each trained on the whole folder, tested like the rest")
    p.add_argument("--groups", metavar="FILE",
                   help="groups of the real folder's images, each also scored on its own: a "
                        "JSON file holding an object of group names, each a list of image "
                        'names ({"asphalt": ["0011", ...], "concrete": [...]})')
    p.add_argument("--steps", type=positive_int, default=300, help="optimiser steps a network")
    p.add_argument("--crop", type=positive_int, default=128,
                   help="training crop side, pixels (multiple of 8)")
    p.add_argument("--batch", type=positive_int, default=8)
    p.add_argument("--width", type=positive_int, default=16,
                   help="U-Net channels at the first level")
    p.add_argument("--learning-rate", type=float, default=2e-3)
    p.add_argument("--test-share", type=float, default=0.3,
                   help="share of the real folder held out for testing; 1 tests on all of "
                        "it and trains no network on it (a folder too small to split)")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--repeats", type=positive_int, default=3,
                   help="networks trained per training set, each from its own draws; the one "
                        "of median F1 is reported, with every repeat's scores (single runs "
                        "scatter: docs/design.md); 1 for a quick look")
    p.add_argument("--device", default="auto",
                   help="auto, cpu, cuda or cuda:N: where the networks train (default: auto, "
                        "CUDA when there is one)")
    p.add_argument("--out", required=True, help="folder for sim2real.json and predictions.png")
    p.set_defaults(func=cmd_bench_sim2real)


def cmd_bench_sim2real(args: argparse.Namespace) -> None:
    from glsynth.model.sim2real import Sim2RealSettings, run_sim2real, summary

    settings = Sim2RealSettings(args.steps, args.crop, args.batch, args.width,
                                args.learning_rate, args.test_share, args.seed, args.repeats,
                                args.device)
    result = run_sim2real(args.synthetic, args.real, args.out, settings, args.other_real,
                          args.groups)
    print(summary(result))
    print(f"-> {args.out}/sim2real.json, predictions.png")


def add_textures_parser(sub: Commands) -> None:
    p = sub.add_parser("textures", help="generate a procedural texture repository folder")
    p.add_argument("--out", required=True, help="repository folder (one sub-folder a category)")
    _add_seed_arg(p, required=False)
    p.add_argument("--count", type=positive_int, default=12, help="images per category")
    p.add_argument("--size", type=int, default=512,
                   help=f"image size in pixels, {TEXTURE_PX[0]} to {TEXTURE_PX[1]}")
    p.set_defaults(func=cmd_textures)


def cmd_textures(args: argparse.Namespace) -> None:
    from glsynth.appearance.repository import generate_repository

    _at_most("--count", args.count, MAX_TEXTURES_PER_CATEGORY, "a category holds")
    if not TEXTURE_PX[0] <= args.size <= TEXTURE_PX[1]:
        raise UserError(f"--size {args.size}: give {TEXTURE_PX[0]} to {TEXTURE_PX[1]} pixels, "
                        "the sizes [materials] builtin_size allows")
    t0 = time.perf_counter()
    root = generate_repository(args.out, args.seed, args.count, args.size)
    print(f"procedural texture repository ({args.count} per category, {args.size} px) in "
          f"{time.perf_counter() - t0:.1f} s -> {root}")


class _Parser(argparse.ArgumentParser):
    """argparse that refuses bad options in one line (the usage block stays with --help), as
    every other bad input is refused; sub-commands' parsers are of this class too."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, clipped(f"{self.prog}: error: {' '.join(message.split())}") + "\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="glsynth", description=__doc__)
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of every error, user errors too")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in (add_export_parser, add_histograms_parser, add_render_parser, add_preview_parser,
                add_generate_parser, add_fly_parser, add_stats_parser, add_train_parser,
                add_evaluate_parser, add_predict_parser, add_assess_parser, add_bench_parser,
                add_textures_parser, add_view_parser):
        add(sub)
    return parser


def one_line(err: BaseException) -> str:
    """An error's message on one line. torch's DataLoader raises a worker's error again with
    the worker's traceback in its message; the line keeps the original message alone."""
    text = str(err)
    if "\nOriginal Traceback" in text:
        last = text.rstrip().splitlines()[-1]
        text = last.partition(": ")[2] or last
    return " ".join(text.split())


def main(argv: Sequence[str] | None = None) -> int:
    """Runs one command. Bad input (UserError) and operating-system errors (permissions, full
    disks, missing files) print one line and return 2; anything else is a programming error
    and keeps its traceback. --debug shows the traceback of every error."""
    args = build_parser().parse_args(argv)
    if args.debug:  # third-party libraries (Ray) show their log lines under --debug only
        logging.getLogger().setLevel(logging.DEBUG)
    with warnings.catch_warnings():  # restores showwarning for a library caller of main
        if not args.debug:  # a warning (a unit or cache entry redone) is one line too
            warnings.showwarning = functools.partial(_warning_line, args.command)
        try:
            _refuse_held_outputs(args)
            return args.func(args) or 0
        except (UserError, OSError) as err:
            if args.debug:
                raise
            print(clipped(f"glsynth {args.command}: error: {one_line(err)}"), file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print(f"glsynth {args.command}: interrupted; run the same command again to resume",
                  file=sys.stderr)
            return 130


def _refuse_held_outputs(args: argparse.Namespace) -> None:
    """No command writes into a folder another run holds: its --out (a folder or a file),
    or, where --out defaults into a run folder (evaluate), that --run."""
    from glsynth.core.runlock import refuse_held

    out = getattr(args, "out", None) or (getattr(args, "run", None)
                                         if args.command == "evaluate" else None)
    if out is not None:
        refuse_held(Path(out))


def _warning_line(command: str, message: Warning | str, *_: object, **__: object) -> None:
    print(clipped(f"glsynth {command}: warning: {' '.join(str(message).split())}"),
          file=sys.stderr)


if __name__ == "__main__":  # the entry point is glsynth.__main__ (it holds Ctrl-C while loading)
    sys.exit("glsynth: run `python -m glsynth` or `glsynth`, not `python -m glsynth.cli`")
