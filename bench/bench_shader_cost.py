"""Where the colour shader's time goes on llvmpipe: the colour-only render time with parts of
shaders/color.frag cut out, at 1920x1080 on the views bench_passes uses.

    .venv/bin/python bench/bench_shader_cost.py [--env 0] [--cameras 8]

Two settings: the paper preset, and MSAA 0 without sky maps and shadows. In the second,
cutting the sky-visibility and shadow code the settings turn off keeps every byte (the bench
checks), so its time is what llvmpipe spends on branches that no pixel takes: it evaluates a
branch for every pixel even when a uniform turns it off for all. The last two variants
replace the lighting by the base texture (textures and normal map only) and by a constant
(the raster and label-pass cost); they change the image by design.

A variant drops code and with it uniforms that the renderer sets: this process's moderngl
programs answer an unknown uniform with a stand-in that takes the write and discards it.
"""

import dataclasses
import hashlib
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import moderngl

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import preset_views, write_results  # noqa: E402

import glsynth.render.gl.programs as programs  # noqa: E402
from glsynth.core.config import Config  # noqa: E402
from glsynth.core.paths import shader_dir  # noqa: E402
from glsynth.render.gl.renderer import Renderer  # noqa: E402
from glsynth.render.view import EnvironmentView  # noqa: E402

SHIPPED = (shader_dir() / "color.frag").read_text()
MAIN = SHIPPED[SHIPPED.index("void main() {"):]


def _cut(old: str, new: str) -> Callable[[str], str]:
    def edit(source: str) -> str:
        if old not in source:
            raise SystemExit(f"color.frag no longer has {old.strip()!r}: update the bench")
        return source.replace(old, new)
    return edit


no_sky = _cut("    vec2 vis = sky_visibility(n, hidden);\n",
              "    vec2 vis = vec2(1.0);\n    hidden = vec3(0.0);\n")
no_sun = _cut("    float sun = sun_visibility(n);", "    float sun = 1.0;")
VARIANTS: dict[str, Callable[[str], str]] = {
    "as shipped": lambda s: s,
    "without the sky-visibility code": no_sky,
    "without the shadow code": no_sun,
    "without both": lambda s: no_sun(no_sky(s)),
    "textures and normal map only": _cut(MAIN, """void main() {
    vec3 view_dir = normalize(-v_view_pos);
    vec3 n = facing_normal(v_normal, view_dir);
    f_normal = vec4(n, 1.0);
    if (u_has_normal_map) n = perturbed_normal(n);
    f_color = vec4(texture(u_base_color_map, v_uv).rgb * n.z, 1.0);
}
"""),
    # Still the shading normal: the MSAA resolve takes its interior pixels by it.
    "constant colour": _cut(MAIN, """void main() {
    f_normal = vec4(facing_normal(v_normal, normalize(-v_view_pos)), 1.0);
    f_color = vec4(0.5 + 1e-6 * fract(v_uv.x));
}
"""),
}
SETTINGS = {"MSAA 0, no sky maps, no shadows": {"msaa": 0, "sky_visibility_maps": 0,
                                                "shadow_map_px": 0},
            "paper preset (MSAA 4, 16 sky maps, 2048 px shadows)": {}}


class _Discard:
    """Takes a uniform write for code a variant cut."""
    value = None

    def write(self, data: bytes) -> None:
        pass


def _lenient_uniforms() -> None:
    known = moderngl.Program.__getitem__

    def get(self: moderngl.Program, name: str):
        try:
            return known(self, name)
        except KeyError:
            return _Discard()
    moderngl.Program.__getitem__ = get


def measure(config: Config, cameras: list[int], source: str, env: int) -> tuple[float, str]:
    """Median colour-only render time (ms) and a digest of the colour of every camera."""
    folder = Path(tempfile.mkdtemp(prefix="glsynth-shaders-"))
    try:
        for f in shader_dir().iterdir():
            if f.is_file():
                shutil.copy(f, folder / f.name)
        (folder / "color.frag").write_text(source)
        programs.shader_dir = lambda: folder
        programs.shader_source.cache_clear()
        view = EnvironmentView.open(config, 0, env, Renderer(config.render))
        color = frozenset({"color"})
        view.render(cameras[0], color)  # compiles llvmpipe's shader variants
        times, digest = [], hashlib.sha256()
        for repeat in range(2):
            for index in cameras:
                t0 = time.perf_counter()
                _, out = view.render(index, color)
                times.append(time.perf_counter() - t0)
                if repeat == 0:
                    digest.update(out.color.tobytes())
        view.renderer.release()
    finally:
        shutil.rmtree(folder)
    return round(1e3 * statistics.median(times), 1), digest.hexdigest()


def main() -> None:
    _lenient_uniforms()
    _, env, base, cameras = preset_views()
    results: dict = {"environment": env, "cameras": cameras, "settings": {}}
    for setting, render in SETTINGS.items():
        config = dataclasses.replace(base, render=dataclasses.replace(base.render, **render))
        rows, shipped = {}, None
        for name, edit in VARIANTS.items():
            ms, digest = measure(config, cameras, edit(SHIPPED), env)
            shipped = shipped or digest
            rows[name] = {"color_ms_median": ms, "same_bytes_as_shipped": digest == shipped}
            print(setting, "|", name, rows[name], flush=True)
        results["settings"][setting] = rows
    write_results("shader_cost", results)


if __name__ == "__main__":
    main()
