"""Where a view's CPU time goes: each render pass, the read-back, and the CPU-side
work of a generated view (filters, label maps, image counts, PNG encoding), as CPU seconds of
the whole process (llvmpipe's threads included) and wall seconds, medians over the cameras.

    .venv/bin/python bench/bench_pass_cpu.py [--preset paper|inspection] [--env 0] [--cameras 8]

Writes bench/results/pass_cpu.json (the paper preset) or pass_cpu_<preset>.json.
CPU seconds are the steadier figure on a shared machine. The GL work is finished before and
after each pass, so the passes do not overlap as they do in a plain render; the sum of the
passes is therefore a little above a plain render's CPU time, given beside it.
"""

import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import preset_views, write_results  # noqa: E402

from glsynth.core.fileio import image_bytes  # noqa: E402
from glsynth.core.filters import removal_reason  # noqa: E402
from glsynth.data.dataset import _FORMATS, _counts, _label_maps  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

PASSES = ("_sky_visibility_pass", "_shadow_pass", "_label_pass", "_color_pass", "_msaa_pass",
          "_read_back")

Timings = defaultdict[str, list[tuple[float, float]]]


def timed(times: Timings, name: str, fn: Callable, finish: Callable[[], None]) -> Callable:
    """``fn`` with its CPU and wall seconds appended to times[name], the GL work finished
    before and after it."""
    def wrapper(*args: object, **kwargs: object) -> object:
        finish()
        cpu, wall = time.process_time(), time.perf_counter()
        out = fn(*args, **kwargs)
        finish()
        times[name].append((time.process_time() - cpu, time.perf_counter() - wall))
        return out
    return wrapper


def measure(times: Timings, name: str, fn: Callable[[], object]) -> object:
    cpu, wall = time.process_time(), time.perf_counter()
    out = fn()
    times[name].append((time.process_time() - cpu, time.perf_counter() - wall))
    return out


def cpu_side(times: Timings, view: EnvironmentView, placement, output) -> None:
    """The generate command's work on a rendered view beside the GL (glsynth.data.dataset)."""
    filters = view.config.filters
    measure(times, "filters", lambda: removal_reason(output.color, output.component,
                                                     output.depth, filters))
    maps, in_rrdr, _ = measure(times, "label maps",
                               lambda: _label_maps(output, placement.camera, filters))
    measure(times, "image counts", lambda: _counts(placement, "train", maps, in_rrdr, []))
    measure(times, "colour PNG", lambda: image_bytes(output.color, "PNG"))
    measure(times, "label files", lambda: [image_bytes(maps[n], f) for n, f in _FORMATS.items()])


def main() -> None:
    preset, env, config, cameras = preset_views(("paper", "inspection"))
    renderer = Renderer(config.render)
    view = EnvironmentView.open(config, 0, env, renderer)
    view.render(cameras[0], photo=False)  # compiles llvmpipe's shader variants
    plain: Timings = defaultdict(list)
    for index in cameras:
        measure(plain, "plain render", lambda i=index: view.render(i, photo=False))
    times: Timings = defaultdict(list)
    for name in PASSES:
        setattr(renderer, name, timed(times, name, getattr(renderer, name),
                                      renderer.ctx.finish))
    for index in cameras:
        placement, output = view.render(index, photo=False)
        cpu_side(times, view, placement, output)
    renderer.release()
    results: dict = {"preset": preset, "environment": env, "cameras": cameras, "ms": {}}
    for name, pairs in {**plain, **times}.items():
        results["ms"][name.strip("_")] = {
            "cpu_median": round(1e3 * statistics.median(c for c, _ in pairs), 1),
            "wall_median": round(1e3 * statistics.median(w for _, w in pairs), 1)}
    write_results("pass_cpu" if preset == "paper" else f"pass_cpu_{preset}", results)


if __name__ == "__main__":
    main()
