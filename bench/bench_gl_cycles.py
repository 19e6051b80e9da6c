"""GL objects and memory over repeated scene loads: one renderer loads, renders and releases the
same environment's scene many times, as a generation worker does with environments; reports
live GL buffers after the last release and RSS growth per load.

    .venv/bin/python bench/bench_gl_cycles.py [--cycles 40] [--width 384]
"""

import argparse
import ctypes
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.core.config import Config  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView, preview_config  # noqa: E402


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=40)
    parser.add_argument("--width", type=int, default=384)
    args = parser.parse_args()
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


if __name__ == "__main__":
    main()
