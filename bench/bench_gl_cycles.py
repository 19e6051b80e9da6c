"""GL objects and memory over repeated scene loads: one renderer loads, renders and releases the
same environment's scene many times, as a generation worker does with environments; reports
live GL buffers after the last release and RSS growth per load. With --environments N, one
renderer instead opens N different environments in turn at the paper preset and full size
(each opening releases the previous one), and the RSS after each release is recorded; growth
is reported per 10 environments from the third on (the first two fill the allocator's and
llvmpipe's pools). RSS is always read after malloc_trim, so it follows what is held.

    .venv/bin/python bench/bench_gl_cycles.py [--cycles 40] [--width 384]
    .venv/bin/python bench/bench_gl_cycles.py --environments 12
"""

import argparse
import ctypes
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config, load_config  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView, preview_config  # noqa: E402


def rss_mb() -> float:
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=40)
    parser.add_argument("--width", type=int, default=384)
    parser.add_argument("--environments", type=int, default=0,
                        help="open this many environments at the paper preset instead")
    args = parser.parse_args()
    if args.environments:
        environments(args.environments)
        return
    config = preview_config(Config(), args.width)
    view = EnvironmentView.open(config, 0, 0, Renderer(config.render))
    renderer, camera = view.renderer, view.camera(0).camera
    is_buffer = ctypes.CDLL("libOpenGL.so.0").glIsBuffer
    is_buffer.restype = ctypes.c_ubyte
    start, highest = rss_mb(), 0
    for _ in range(args.cycles):
        renderer.load(view.scene, view.lighting)
        renderer.render(camera)
        probe = renderer.ctx.buffer(reserve=4)
        highest = max(highest, probe.glo)
        probe.release()
        renderer.release_scene()
    end = rss_mb()
    write_results("gl_cycles", {
        "cycles": args.cycles, "size": [config.render.width, config.render.height],
        "parts_per_scene": len(view.scene.parts),
        "live_buffers_after_release": sum(is_buffer(n) for n in range(1, highest + 1)),
        "rss_start_mb": round(start, 1), "rss_end_mb": round(end, 1),
        "rss_growth_per_load_mb": round((end - start) / args.cycles, 3)})
    renderer.release()


def environments(count: int) -> None:
    if count < 3:
        raise SystemExit(f"--environments {count}: give at least 3")
    config = load_config("paper")
    renderer = Renderer(config.render)
    rss = []
    for env in range(count):
        view = EnvironmentView.open(config, 0, env, renderer)
        view.render(0)
        renderer.release_scene()
        rss.append(round(rss_mb(), 1))
        del view
    write_results("gl_cycles_environments", {
        "preset": "paper", "environments": count,
        "rss_after_release_mb": rss,
        "rss_growth_per_10_environments_mb": round(
            (rss[-1] - rss[2]) / (count - 3) * 10, 1)})
    renderer.release()


if __name__ == "__main__":
    main()
