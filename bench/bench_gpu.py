"""glsynth on a GPU: which EGL device draws, whether it draws the CPU's labels and depth, how
many samples a second it renders, and how fast FCN58 trains there. bench/gpu.sh runs it
unattended after setting up; it also runs alone:

    .venv/bin/python bench/bench_gpu.py --out out/gpu [--views 8] [--train-steps 20]

Steps, each in a child process so that each draws on one GL device:
1. devices: an EGL context for each GLCONTEXT_DEVICE_INDEX until one fails, named as the driver
   names it; the first that is not Mesa's software rasterizer is the GPU. None: one line, exit 2.
2. render: the paper preset's environment 0, ``--views`` cameras spread over it, every pass,
   once on the GPU (EGL at that index) and once on the CPU (OSMesa, llvmpipe); the opening and
   each view timed.
3. compare: component and damage ids must be identical, depth within 1e-6 relative (where a
   surface was hit); the fraction of equal pixels is reported either way.
4. train: FCN58 forward, backward and Adam on a fixed batch of 8 at 642x360 and 1920x1080,
   ``--train-steps`` steps each after one warm-up, bf16 autocast where the GPU supports it.
Writes OUT/gpu.json (and OUT/*.npz, the rendered maps); prints the summary.
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

SOFTWARE = ("llvmpipe", "softpipe", "swrast")
DEPTH_RTOL = 1e-6
MAX_DEVICES = 16


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


def render_views(out: Path, n_views: int) -> dict:
    """In a child: open the paper environment 0 on this process's GL and render the views."""
    from glsynth.core.config import load_config
    from glsynth.render.gl.context import device_name
    from glsynth.render.view import EnvironmentView

    config = load_config("paper")
    t0 = time.perf_counter()
    view = EnvironmentView.open(config, 0, 0)
    opening = time.perf_counter() - t0
    total = config.cameras.total
    cameras = sorted({round(i * (total - 1) / max(1, n_views - 1)) for i in range(n_views)})
    maps, times = {}, []
    with view.renderer:
        view.render(cameras[0])  # warm-up: programs linked, textures resident
        for index in cameras:
            t0 = time.perf_counter()
            _, output = view.render(index)
            times.append(time.perf_counter() - t0)
            for name in ("component", "damage", "depth"):
                maps[f"{name}_{index:03d}"] = getattr(output, name)
        device = device_name(view.renderer.ctx)
    np.savez(out, **maps)
    return {"device": device, "opening_s": opening, "view_s": statistics.median(times),
            "views": len(cameras), "samples_per_s": len(times) / sum(times)}


def compare(gpu: Path, cpu: Path) -> dict:
    """Labels identical and depth within DEPTH_RTOL, with the shares that agree."""
    with np.load(gpu) as a, np.load(cpu) as b:
        equal, pixels, worst = {"component": 0, "damage": 0}, 0, 0.0
        for key in a.files:
            kind = key.rsplit("_", 1)[0]
            if kind == "depth":
                hit = np.isfinite(b[key]) & (b[key] > 0)
                rel = np.abs(a[key][hit] - b[key][hit]) / b[key][hit]
                worst = max(worst, float(rel.max(initial=0.0)))
            else:
                equal[kind] += int((a[key] == b[key]).sum())
                pixels += a[key].size if kind == "component" else 0
    shares = {kind: count / pixels for kind, count in equal.items()}
    return {"label_share_equal": shares, "depth_max_rel": worst,
            "labels_identical": all(s == 1.0 for s in shares.values()),
            "depth_within_rtol": worst <= DEPTH_RTOL, "depth_rtol": DEPTH_RTOL}


def train_steps(steps: int) -> dict:
    """In a child: seconds per image of an FCN58 step on the GPU, at two sizes."""
    import torch
    from glsynth.model.fcn58 import FCN58
    from glsynth.model.losses import weighted_cross_entropy

    if not torch.cuda.is_available():
        raise NoGPU("torch sees no CUDA device; install torch==2.13.0 with CUDA (PyPI's "
                    "Linux wheel) and the NVIDIA driver")
    device, bf16 = torch.device("cuda"), torch.cuda.is_bf16_supported()
    results = {"device": torch.cuda.get_device_name(0), "bf16": bf16}
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/gpu"))
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--train-steps", type=int, default=20)
    parser.add_argument("step", nargs="?", default="all", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.step == "_name":
        from glsynth.render.gl.context import create_context, device_name
        print(device_name(create_context()[0]))
        return 0
    if args.step in ("_render", "_train"):
        result = (render_views(args.out, args.views) if args.step == "_render"
                  else train_steps(args.train_steps))
        print(json.dumps(result))
        return 0
    try:
        names = egl_devices()
        index = gpu_index(names)
    except NoGPU as err:
        print(f"bench_gpu: {err}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    gpu_env = {"GLSYNTH_GL_PLATFORM": "egl", "GLCONTEXT_DEVICE_INDEX": str(index)}
    common = ["--views", str(args.views), "--train-steps", str(args.train_steps)]
    results = {"command": "python " + " ".join(sys.argv), "egl_devices": names,
               "gpu_index": index}
    print(f"bench_gpu: EGL device {index} is the GPU: {names[index]}", flush=True)
    results["gpu"] = _run_child(["_render", "--out", str(args.out / "gpu.npz"), *common],
                                gpu_env)
    results["cpu"] = _run_child(["_render", "--out", str(args.out / "cpu.npz"), *common],
                                {"GLSYNTH_GL_PLATFORM": "osmesa"})
    results["agreement"] = compare(args.out / "gpu.npz", args.out / "cpu.npz")
    results["train"] = _run_child(["_train", *common], {})
    (args.out / "gpu.json").write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
