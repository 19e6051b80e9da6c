"""Per-pass render timings at 1920x1080 on typical viaduct views, against the raw floor (the
least a full sample needs on the same scene and GL), and against pyrender's own renderer.

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


_FLOOR_VERTEX = """#version 330 core
uniform mat4 u_mvp;
in vec3 in_position;
void main() { gl_Position = u_mvp * vec4(in_position, 1.0); }
"""
_FLOOR_FRAGMENT = """#version 330 core
uniform vec4 u_value;
out vec4 f_value;
void main() { f_value = u_value; }
"""


def time_floor(view: EnvironmentView, cameras: list[int], repeats: int) -> float:
    """The raw floor of a full sample on the same scene and GL context: every mesh uploaded as
    bare positions and drawn twice, nearest first, with a constant-colour shader into an RGBA8
    and an RGBA32F target with depth tests, both read back; no textures, no lighting, no
    shadows. glsynth's full sample at MSAA 0 is compared with it."""
    import moderngl
    import numpy as np

    ctx, size = view.renderer.ctx, view.renderer.size
    prog = ctx.program(vertex_shader=_FLOOR_VERTEX, fragment_shader=_FLOOR_FRAGMENT)
    scene = view.scene.scene
    meshes = []  # (pose, centre, vao, buffers)
    for node in scene.mesh_nodes:
        pose = scene.get_pose(node)
        for primitive in node.mesh.primitives:
            vbo = ctx.buffer(primitive.positions.astype("f4").tobytes())
            ibo = ctx.buffer(primitive.indices.astype("u4").tobytes())
            vao = ctx.vertex_array(prog, [(vbo, "3f", "in_position")], ibo, 4)
            centre = pose[:3, :3] @ primitive.positions.mean(0) + pose[:3, 3]
            meshes.append((pose, centre, vao, (vbo, ibo)))
    targets = [ctx.framebuffer([ctx.renderbuffer(size, 4, dtype=dtype)],
                               ctx.depth_renderbuffer(size)) for dtype in ("f1", "f4")]
    times = []
    for index in cameras:
        camera = view.camera(index).camera
        clip = camera.projection() @ camera.view()
        eye = camera.pose[:3, 3]
        for repeat in range(repeats + 1):  # the first one warms up
            t0 = time.perf_counter()
            order = sorted(meshes, key=lambda m: float(np.sum((m[1] - eye) ** 2)))
            for fbo, components, dtype in zip(targets, (3, 4), ("f1", "f4"), strict=True):
                fbo.use()
                fbo.clear(0.0, 0.0, 0.0, 0.0)
                ctx.enable(moderngl.DEPTH_TEST)
                for k, (pose, _, vao, _) in enumerate(order):
                    prog["u_mvp"].write((clip @ pose).astype("f4").T.tobytes())
                    prog["u_value"].value = (k / len(order), 0.5, 0.5, 1.0)
                    vao.render()
                fbo.read(components=components, dtype=dtype)
            if repeat:
                times.append(time.perf_counter() - t0)
    for _, _, vao, buffers in meshes:
        vao.release()
        for buffer in buffers:
            buffer.release()
    for fbo in targets:
        for attachment in (*fbo.color_attachments, fbo.depth_attachment):
            attachment.release()
        fbo.release()
    prog.release()
    return median_ms(times)


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
            floor = time_floor(view, cameras, args.repeats)
            results["raw floor of a full sample (ms)"] = floor
            results["full sample at msaa 0 / raw floor"] = round(
                results["glsynth msaa=0 (ms)"]["full sample"] / floor, 2)
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
