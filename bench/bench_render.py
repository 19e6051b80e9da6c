"""Per-pass render timings at 1920x1080 on typical viaduct views, against pyrender's own
renderer on the same scene and against the Blender Cycles times measured on this machine.

    .venv/bin/python bench/bench_render.py [--cameras 10] [--repeats 3] [--no-pyrender]

Medians over cameras spread across the 100 of environment 0 (regular and close-up), each
repeated; read-back and the conversion to numpy are included in every figure.
"""

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # for pyrender's own renderer (comparison)

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402


def median_ms(values: list[float]) -> float:
    return round(statistics.median(values) * 1000, 1)


def render_ms(renderer: Renderer, view: EnvironmentView, cameras: list[int], repeats: int,
              passes: set[str]) -> float:
    """Median over cameras x repeats, each camera warmed up once (first use of each state)."""
    times = []
    for index in cameras:
        camera = view.camera(index).camera
        renderer.render(camera, passes)
        for _ in range(repeats):
            t0 = time.perf_counter()
            renderer.render(camera, passes)
            times.append(time.perf_counter() - t0)
    return median_ms(times)


def time_passes(view: EnvironmentView, cameras: list[int], repeats: int) -> dict:
    runs = {"color": {"color"}, "labels+depth": {"component", "damage", "depth"},
            "full sample": {"color", "component", "damage", "depth"}}
    return {name: render_ms(view.renderer, view, cameras, repeats, passes)
            for name, passes in runs.items()}


def time_shadow_sizes(view: EnvironmentView, cameras: list[int], repeats: int) -> dict:
    """The colour pass (MSAA 0) with each shadow-map size; 0 is no shadows."""
    out = {}
    for px in (0, 1024, 2048, 4096):
        renderer = Renderer(dataclasses.replace(view.config.render, msaa=0, shadow_map_px=px),
                            platform="egl")
        renderer.load(view.scene, view.lighting)
        out[f"shadow_map_px={px}"] = render_ms(renderer, view, cameras, repeats, {"color"})
        renderer.release()
    return out


def time_pyrender(view: EnvironmentView, cameras: list[int], repeats: int) -> dict:
    import numpy as np
    import pyrender

    cfg = view.config.render
    r = pyrender.OffscreenRenderer(cfg.width, cfg.height)
    scene = view.scene.scene
    scene.add(pyrender.DirectionalLight(intensity=3.0), pose=np.eye(4))
    out = {}
    for name, flags in (("color (MSAA 4x, pyrender PBR)", pyrender.RenderFlags.NONE),
                        ("depth only", pyrender.RenderFlags.DEPTH_ONLY),
                        ("flat segmentation", pyrender.RenderFlags.SEG)):
        times = []
        for index in cameras:
            cam = view.camera(index).camera
            k = cam.K
            node = scene.add(pyrender.IntrinsicsCamera(k[0, 0], k[1, 1], k[0, 2], k[1, 2],
                                                       cam.znear, cam.zfar), pose=cam.pose)
            kw = {"seg_node_map": {n: (1, 2, 3) for n in scene.mesh_nodes}} \
                if flags == pyrender.RenderFlags.SEG else {}
            r.render(scene, flags, **kw)
            for _ in range(repeats):
                t0 = time.perf_counter()
                r.render(scene, flags, **kw)
                times.append(time.perf_counter() - t0)
            scene.remove_node(node)
        out[name] = median_ms(times)
    r.delete()
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cameras", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-pyrender", action="store_true")
    args = parser.parse_args()
    config = Config()
    cameras = [round(i * 99 / (args.cameras - 1)) for i in range(args.cameras)]
    results: dict = {"size": [config.render.width, config.render.height], "cameras": cameras}
    for msaa in (0, 4):
        cfg = dataclasses.replace(config, render=dataclasses.replace(config.render, msaa=msaa))
        view = EnvironmentView.open(cfg, 0, 0, Renderer(cfg.render, platform="egl"))
        results[f"glsynth msaa={msaa} (ms)"] = time_passes(view, cameras, args.repeats)
        if msaa == 0:
            results["colour pass by shadow map size (ms)"] = time_shadow_sizes(
                view, cameras, args.repeats)
        view.renderer.release()
    # Cycles on the same view, timed in the same run: `glsynth bench blender`.
    if not args.no_pyrender:
        view = EnvironmentView.open(config, 0, 0, Renderer(config.render, platform="egl"))
        results["pyrender 0.1.45 OffscreenRenderer (ms)"] = time_pyrender(view, cameras,
                                                                          args.repeats)
    write_results("render", results)


if __name__ == "__main__":
    main()
