"""glsynth on a GPU: which EGL device draws, whether it draws the CPU's labels, depth and
crack widths, how many samples a second it renders, and how fast FCN58 trains there.
bench/gpu.sh runs it unattended after setting up; it also runs alone:

    .venv/bin/python bench/bench_gpu.py --out out/gpu [--views 4] [--train-steps 20]
    .venv/bin/python bench/bench_gpu.py --out ref --cpu-only        # on a machine with Mesa
    python3 bench/bench_gpu.py --out out/gpu --cpu-reference ref    # on a GPU without it

Steps, each in a child process so that each draws on one GL device:
1. devices: an EGL context for each GLCONTEXT_DEVICE_INDEX until one fails, named as the driver
   names it; the first that is not Mesa's software rasterizer is the GPU. None: one line, exit 2.
2. render, for each of ``--presets`` (the paper preset, and the inspection preset, whose
   crack shader the paper preset never runs): environment 0, ``--views`` cameras spread over
   it, every pass, once on the GPU (EGL at that index) and once on the CPU (OSMesa,
   llvmpipe); the opening and each view timed. A GPU machine without Mesa (a cloud image with
   only the NVIDIA driver) takes the CPU's maps from ``--cpu-reference``, the folder that
   ``--cpu-only`` wrote elsewhere with the same ``--views`` and presets; the library
   versions of both renders are recorded beside the comparison, since a different numpy or
   OpenCV can move a scene before any GL runs.
3. compare: component and damage ids, counting apart the pixels where the two differ only by
   a rasterizer's tie at an edge; depth within 1e-6 relative where both saw the same
   component; crack pixels and their widths where a preset draws cracks. The shares that
   agree are reported either way.
4. train: FCN58 forward, backward and Adam on a fixed batch of 8 at 642x360 and 1920x1080,
   ``--train-steps`` steps each after one warm-up, bf16 autocast where the GPU supports it.
Writes OUT/gpu.json (and OUT/gpu_<preset>.npz, the rendered maps); prints the summary.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from glsynth.core.errors import UserError

SOFTWARE = ("llvmpipe", "softpipe", "swrast")
DEPTH_RTOL = 1e-6
MAX_DEVICES = 16
PRESETS = ("paper", "inspection")
MAPS = ("component", "damage", "depth", "crack_width")


class NoGPU(Exception):
    """No EGL device here is a GPU."""


def _child(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, __file__, *args], env=dict(os.environ, **env),
                          capture_output=True, text=True)


def egl_devices() -> list[str]:
    """The name of each EGL device, by GLCONTEXT_DEVICE_INDEX, until an index fails."""
    names = []
    for index in range(MAX_DEVICES):
        done = _child(["_name"], {"GLSYNTH_GL_PLATFORM": "egl",
                                  "GLCONTEXT_DEVICE_INDEX": str(index)})
        if done.returncode != 0:
            break
        names.append(done.stdout.strip())
    return names


def gpu_index(names: list[str]) -> int:
    for index, name in enumerate(names):
        if not any(word in name.lower() for word in SOFTWARE):
            return index
    raise NoGPU(f"no EGL device is a GPU (found: {names or 'none'}); install the GPU's EGL "
                "driver (for NVIDIA, libnvidia-gl with its glvnd EGL vendor file)")


def render_views(out: Path, preset: str, n_views: int) -> dict:
    """In a child: open ``preset``'s environment 0 on this process's GL and render the
    views."""
    from glsynth.core.config import load_config
    from glsynth.render.gl.context import device_name
    from glsynth.render.view import EnvironmentView

    config = load_config(preset)
    t0 = time.perf_counter()
    view = EnvironmentView.open(config, 0, 0)
    opening = time.perf_counter() - t0
    cameras = camera_indices(config.cameras.total, n_views)
    maps, times = {}, []
    with view.renderer:
        view.render(cameras[0])  # warm-up: programs linked, textures resident
        for index in cameras:
            t0 = time.perf_counter()
            _, output = view.render(index)
            times.append(time.perf_counter() - t0)
            for name in MAPS:
                if getattr(output, name, None) is not None:  # a pass a preset may not have
                    maps[f"{name}_{index:03d}"] = getattr(output, name)
        device = device_name(view.renderer.ctx)
    np.savez_compressed(out, **maps)
    return {"preset": preset, "device": device, "opening_s": opening,
            "view_s": statistics.median(times), "views": len(cameras),
            "samples_per_s": len(times) / sum(times),
            "versions": versions()}


def camera_indices(total: int, n_views: int) -> list[int]:
    """``n_views`` cameras spread evenly over an environment's ``total`` (fewer where they
    round to the same one)."""
    return sorted({round(i * (total - 1) / max(1, n_views - 1)) for i in range(n_views)})


def versions() -> dict[str, str]:
    """The versions of what builds and draws a scene, so two renders can be matched up."""
    import cv2
    import moderngl
    import scipy
    import trimesh

    return {"python": sys.version.split()[0], "numpy": np.__version__, "scipy": scipy.__version__,
            "opencv": cv2.__version__, "moderngl": moderngl.__version__,
            "trimesh": trimesh.__version__}


def in_neighbourhood(values: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Pixels whose value in ``values`` is some label among their 3x3 neighbours in
    ``labels``."""
    padded = np.pad(labels, 1, mode="edge")
    h, w = labels.shape
    found = np.zeros(labels.shape, bool)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            found |= padded[dy:dy + h, dx:dx + w] == values
    return found


def edge_ties(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pixels where two label maps differ by a rasterizer's tie: each map's label lies next
    to the pixel in the other map, as when an edge between two labels moves by a pixel. A
    label dropped whole (a thin crack missing) or a third label on an edge is no tie."""
    return in_neighbourhood(a, b) & in_neighbourhood(b, a)


def compare(gpu: Path, cpu: Path) -> dict:
    """How far the GPU's maps agree with the CPU's. Two rasterizers may round a pixel centre
    that lies within float error of a triangle edge to different sides, so a differing label
    is counted apart where it is such a tie (edge_ties); depth is compared where both hit the
    same component (elsewhere the two saw different surfaces); crack widths where both drew a
    crack (``crack``, where the maps hold crack widths)."""
    with np.load(gpu) as a, np.load(cpu) as b:
        if set(a.files) != set(b.files):
            raise ValueError(f"{cpu} holds other views than {gpu} ({sorted(b.files)[:3]}... "
                             f"against {sorted(a.files)[:3]}...): make it with the same --views")
        views = sorted({key.rsplit("_", 1)[1] for key in a.files})
        pixels, rel, cracks = 0, [], []
        differ = {kind: 0 for kind in ("component", "damage")}
        off_edge = dict(differ)
        for view in views:
            # Each access to an npz member reads and inflates it again: once per map.
            ga, gb = ({kind: z[f"{kind}_{view}"] for kind in MAPS if f"{kind}_{view}" in z}
                      for z in (a, b))
            for kind in differ:
                wrong = ga[kind] != gb[kind]
                differ[kind] += int(wrong.sum())
                off_edge[kind] += int((wrong & ~edge_ties(ga[kind], gb[kind])).sum())
            depth_a, depth_b = ga["depth"], gb["depth"]
            same = (ga["component"] == gb["component"]) & np.isfinite(depth_b) & (depth_b > 0)
            rel.append(np.abs(depth_a[same] - depth_b[same]) / depth_b[same])
            pixels += depth_b.size
            if "crack_width" in ga:
                cracks.append(crack_agreement(ga["crack_width"], gb["crack_width"]))
    rel = np.concatenate(rel)
    result = {
        "pixels": pixels, "labels_differ": differ, "labels_differ_off_edges": off_edge,
        "label_share_equal": {kind: 1 - n / pixels for kind, n in differ.items()},
        "labels_identical": not any(differ.values()),
        "labels_identical_off_edges": not any(off_edge.values()),
        "depth_rtol": DEPTH_RTOL, "depth_max_rel": float(rel.max(initial=0.0)),
        "depth_share_within_rtol": float((rel <= DEPTH_RTOL).mean()) if rel.size else 1.0,
        "depth_rel_99_99": float(np.quantile(rel, 0.9999)) if rel.size else 0.0,
        "depth_within_rtol": bool(rel.max(initial=0.0) <= DEPTH_RTOL)}
    if cracks:
        result["crack"] = sum_cracks(cracks)
    return result


def crack_agreement(gpu: np.ndarray, cpu: np.ndarray) -> dict:
    """One view's crack-width maps (mm, 0 where no crack): the pixels each calls cracked,
    those only one does (apart, those that are no tie at a crack's edge) and the relative
    width error where both do."""
    on_gpu, on_cpu = gpu > 0, cpu > 0
    wrong = on_gpu != on_cpu
    ties = edge_ties(on_gpu.astype(np.uint8), on_cpu.astype(np.uint8))
    both = on_gpu & on_cpu
    # On two-valued maps a tie is a crack pixel beside the other map's crack: a crack drawn
    # a pixel wider all along would count as ties, so each side's own pixels are given too.
    return {"gpu": int(on_gpu.sum()), "cpu": int(on_cpu.sum()), "differ": int(wrong.sum()),
            "gpu_only": int((on_gpu & ~on_cpu).sum()), "cpu_only": int((on_cpu & ~on_gpu).sum()),
            "differ_off_edges": int((wrong & ~ties).sum()),
            "width_rel": np.abs(gpu[both] - cpu[both]) / cpu[both]}


def sum_cracks(views: list[dict]) -> dict:
    """crack_agreement's views together: counts summed, width errors as median and max."""
    rel = np.concatenate([view["width_rel"] for view in views])
    counts = {key: sum(view[key] for view in views)
              for key in ("gpu", "cpu", "differ", "gpu_only", "cpu_only", "differ_off_edges")}
    return {"pixels_" + key: value for key, value in counts.items()} | {
        "width_median_rel": float(np.median(rel)) if rel.size else 0.0,
        "width_max_rel": float(rel.max(initial=0.0))}


def train_steps(steps: int) -> dict:
    """In a child: seconds per image of an FCN58 step on the GPU, at two sizes."""
    import torch
    from glsynth.model.fcn58 import FCN58
    from glsynth.model.losses import weighted_cross_entropy

    if not torch.cuda.is_available():
        raise NoGPU("torch sees no CUDA device; install torch==2.13.0 with CUDA (PyPI's "
                    "Linux wheel) and the NVIDIA driver")
    device, bf16 = torch.device("cuda"), torch.cuda.is_bf16_supported()
    results = {"device": torch.cuda.get_device_name(0), "bf16": bf16,
               "torch": torch.__version__, "cuda": torch.version.cuda}
    for w, h in ((642, 360), (1920, 1080)):
        model = FCN58(8).to(device, memory_format=torch.channels_last)
        optimizer = torch.optim.Adam(model.parameters(), 1e-3, weight_decay=1e-4)
        images = torch.rand(8, 3, h, w, device=device).contiguous(
            memory_format=torch.channels_last)
        labels = torch.randint(0, 9, (8, -(-h // 3), -(-w // 3)), device=device)
        weights = torch.ones(8, device=device)
        times = []
        for step in range(steps + 1):
            torch.cuda.synchronize()
            t0 = time.perf_counter()
            with torch.autocast("cuda", dtype=torch.bfloat16, enabled=bf16):
                loss = weighted_cross_entropy(model(images), labels, weights)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            torch.cuda.synchronize()
            if step:
                times.append(time.perf_counter() - t0)
        results[f"{w}x{h}"] = {"s_per_image": statistics.median(times) / 8, "steps": steps}
    return results


def _run_child(args: list[str], env: dict[str, str]) -> dict:
    done = _child(args, env)
    if done.returncode != 0:
        lines = (done.stderr or done.stdout).strip().splitlines() or ["no output"]
        raise RuntimeError(f"{args[0]} failed: {lines[-1]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def render_on_cpu(out: Path, preset: str, common: list[str]) -> dict:
    """``preset``'s views rendered on OSMesa (llvmpipe) in a child, their maps written to
    ``out``."""
    return _run_child(["_render", "--out", str(out), "--presets", preset, *common],
                      {"GLSYNTH_GL_PLATFORM": "osmesa"})


def reference_files(reference: Path, preset: str) -> tuple[Path, Path]:
    """The maps and figures that ``--cpu-only`` wrote for ``preset`` into ``reference``."""
    return reference / f"cpu_{preset}.npz", reference / f"cpu_{preset}.json"


def check_inputs(presets: list[str], reference: Path | None, n_views: int) -> None:
    """Before any render: every preset is one glsynth knows, and a --cpu-reference is a
    --cpu-only output holding each preset's maps and figures, of as many views."""
    from glsynth.core.config import load_config

    totals = {preset: load_config(preset).cameras.total for preset in presets}  # else UserError
    if reference is None:
        return
    for preset in presets:
        maps, figures = reference_files(reference, preset)
        views = (json.loads(figures.read_text()).get("views") if figures.is_file() and
                 maps.is_file() else None)
        if views != len(camera_indices(totals[preset], n_views)):
            missing = maps.name if not maps.is_file() else figures.name
            found = f"{views} views, not --views {n_views}'s" if views else f"no {missing}"
            raise ValueError(f"--cpu-reference {reference}: {found} for {preset}; make it on "
                             "a machine with Mesa with `bench_gpu.py --out DIR --cpu-only` "
                             "and the same --views and --presets")


def _save(out: Path, results: dict) -> None:
    (out / "gpu.json").write_text(json.dumps(results, indent=2) + "\n")


def cpu_only(out: Path, presets: list[str], common: list[str]) -> None:
    """The reference a GPU machine without Mesa compares with: OUT/cpu_<preset>.npz/.json."""
    out.mkdir(parents=True, exist_ok=True)
    for preset in presets:
        maps, figures = reference_files(out, preset)
        cpu = render_on_cpu(maps, preset, common)
        figures.write_text(json.dumps(cpu, indent=2) + "\n")
        print(json.dumps(cpu, indent=2))


def render_and_compare(args: argparse.Namespace, results: dict, gpu_env: dict[str, str],
                       common: list[str]) -> None:
    """Each preset on the GPU, then on the CPU or from the reference, then compared; the
    results file saved after each step, so that a failure keeps what came before."""
    renders = results["renders"] = {}
    for preset in args.presets:
        maps = args.out / f"gpu_{preset}.npz"
        renders[preset] = {"gpu": _run_child(
            ["_render", "--out", str(maps), "--presets", preset, *common], gpu_env)}
        _save(args.out, results)
        if args.cpu_reference:
            reference, figures = reference_files(args.cpu_reference, preset)
            renders[preset]["cpu"] = json.loads(figures.read_text())
        else:
            reference = args.out / f"cpu_{preset}.npz"
            renders[preset]["cpu"] = render_on_cpu(reference, preset, common)
        renders[preset]["agreement"] = compare(maps, reference)
        _save(args.out, results)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/gpu"))
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--presets", nargs="+", default=list(PRESETS),
                        help="the presets rendered and compared (environment 0 of each)")
    parser.add_argument("--train-steps", type=int, default=20)
    parser.add_argument("--cpu-only", action="store_true",
                        help="render the views on the CPU (OSMesa) into OUT/cpu_<preset>.npz "
                             "and stop")
    parser.add_argument("--cpu-reference", type=Path, default=None,
                        help="compare with this --cpu-only folder instead of rendering on the "
                             "CPU")
    parser.add_argument("step", nargs="?", default="all", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.step == "_name":
        from glsynth.render.gl.context import create_context, device_name
        print(device_name(create_context()[0]))
        return 0
    if args.step in ("_render", "_train"):
        result = (render_views(args.out, args.presets[0], args.views)
                  if args.step == "_render" else train_steps(args.train_steps))
        print(json.dumps(result))
        return 0
    common = ["--views", str(args.views), "--train-steps", str(args.train_steps)]
    try:
        check_inputs(args.presets, args.cpu_reference, args.views)
        if args.cpu_only:
            cpu_only(args.out, args.presets, common)
            return 0
        names = egl_devices()
        index = gpu_index(names)
    except (NoGPU, ValueError, UserError) as err:
        print(f"bench_gpu: {err}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    gpu_env = {"GLSYNTH_GL_PLATFORM": "egl", "GLCONTEXT_DEVICE_INDEX": str(index)}
    results = {"command": "python " + " ".join(sys.argv), "egl_devices": names,
               "gpu_index": index}
    print(f"bench_gpu: EGL device {index} is the GPU: {names[index]}", flush=True)
    try:
        render_and_compare(args, results, gpu_env, common)
    except ValueError as err:  # a reference of other views
        print(f"bench_gpu: {err}", file=sys.stderr)
        return 2
    results["train"] = _run_child(["_train", *common], {})
    _save(args.out, results)
    print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
