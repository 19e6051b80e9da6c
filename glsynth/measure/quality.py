"""Quality presets, from ``preview`` to ``reference``, and the measured trade between speed and
accuracy (``glsynth bench quality``).

A preset sets these knobs of a config (each documented in README.md):
- render resolution, as a scale of 1920x1080 (the Tokaido format needs 1.0);
- MSAA samples for colour (labels and depth are never multisampled);
- texture resolution of repository materials, and of damage textures;
- noise octaves of the damage textures;
- tessellation of cylinders (poles and wires; rebar lives in the damage textures);
- the sun's shadow map size (0: no shadows).
"""

import dataclasses
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.core.config import Config
from glsynth.core.errors import UserError
from glsynth.core.images import nearest_resize


@dataclass(frozen=True)
class Quality:
    render_scale: float
    msaa: int
    texture_size: int
    damage_resolution: int
    octaves: int
    cylinder_segments: int
    shadow_map_px: int


QUALITY = {
    "preview": Quality(0.25, 0, 128, 256, 4, 6, 0),
    "fast": Quality(0.5, 0, 256, 512, 6, 8, 1024),
    "balanced": Quality(1.0, 0, 512, 1024, 8, 12, 2048),
    "default": Quality(1.0, 4, 512, 1024, 8, 12, 2048),
    "high": Quality(1.0, 4, 512, 2048, 8, 12, 2048),
    "reference": Quality(1.0, 4, 1024, 2048, 8, 24, 4096),
}
"""'default' is Config()'s own setting; 'high' matches the paper preset's 2048 px damage.
'reference' uses MSAA 4, the most llvmpipe offers (the renderer refuses more than the GL has)."""


def apply_quality(config: Config, name: str) -> Config:
    if name not in QUALITY:
        raise UserError(f"quality {name!r}: choose one of {', '.join(QUALITY)}")
    q = QUALITY[name]
    width, height = round(1920 * q.render_scale), round(1080 * q.render_scale)
    return dataclasses.replace(
        config,
        render=dataclasses.replace(config.render, width=width, height=height, msaa=q.msaa,
                                   shadow_map_px=q.shadow_map_px),
        materials=dataclasses.replace(config.materials, texture_size=q.texture_size),
        damage=dataclasses.replace(config.damage, resolution=q.damage_resolution,
                                   octaves=q.octaves),
        environment=dataclasses.replace(config.environment,
                                        cylinder_segments=q.cylinder_segments))


def _upsample(values: np.ndarray, shape: tuple[int, int], nearest: bool) -> np.ndarray:
    """To the reference size: nearest for ids and depth edges, bilinear for colour."""
    if nearest or values.shape[:2] == shape:
        return nearest_resize(values, shape)
    from PIL import Image

    return np.asarray(Image.fromarray(values).resize((shape[1], shape[0]),
                                                     Image.Resampling.BILINEAR))


def label_scores(output, truth, zfar: float) -> dict:
    """Component and damage label agreement, median relative depth error and damaged-area
    error (percentage points) of one view against another of the same camera (any size)."""
    shape = truth.component.shape
    comp = _upsample(output.component, shape, nearest=True)
    dmg = _upsample(output.damage, shape, nearest=True)
    depth = _upsample(output.depth, shape, nearest=True)
    hit = (truth.depth < zfar) & (depth < zfar)
    rel = np.abs(depth[hit] - truth.depth[hit]) / truth.depth[hit]
    return {"component_agreement": float((comp == truth.component).mean()),
            "damage_agreement": float((dmg == truth.damage).mean()),
            "depth_median_rel_error": float(np.median(rel)) if rel.size else 0.0,
            "damaged_area_error_pp": float(100 * abs((dmg >= 2).mean() -
                                                     (truth.damage >= 2).mean()))}


def compare(output, reference, zfar: float) -> dict:
    """Colour PSNR/SSIM and the label scores of one view against the reference preset's."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    color = _upsample(output.color, reference.component.shape, nearest=False)
    identical = np.array_equal(reference.color, color)  # PSNR is infinite: report 99 dB
    psnr = 99.0 if identical else peak_signal_noise_ratio(reference.color, color, data_range=255)
    return {"psnr_db": float(min(psnr, 99.0)),
            "ssim": float(structural_similarity(reference.color, color, channel_axis=2,
                                                data_range=255)),
            **label_scores(output, reference, zfar)}


def bench_quality(config: Config, root_seed: int, env: int, cameras: list[int],
                  out: Path, presets: list[str] | None = None) -> dict:
    """Render the same views under each preset; time them and compare with 'reference' and
    with an Embree ray cast of the reference scene (labels and depth)."""
    from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
    from glsynth.render.raycast import ray_cast
    from glsynth.render.view import EnvironmentView

    presets = presets or list(QUALITY)
    order = ["reference"] + [p for p in presets if p != "reference"]
    outputs, rows, truths = {}, {}, []
    for name in order:
        cfg = apply_quality(config, name)
        t0 = time.perf_counter()
        view = EnvironmentView.open(cfg, root_seed, env)
        opened = time.perf_counter() - t0
        renders, times, placements = [], [], []
        try:
            for index in cameras:
                t = time.perf_counter()
                placement, output = view.render(index)
                times.append(time.perf_counter() - t)
                renders.append(output)
                placements.append(placement)
            if name == "reference":
                parts, materials = view.environment.parts, view.dressing.materials
                truths = [ray_cast(parts, materials, p.camera) for p in placements]
        finally:
            view.renderer.release()
        outputs[name] = renders
        n_cameras = cfg.cameras.total
        render_s = statistics.median(times)
        rows[name] = {**dataclasses.asdict(QUALITY[name]),
                      "width": cfg.render.width, "height": cfg.render.height,
                      "render_s": render_s, "open_s": opened,
                      "time_per_sample_s": render_s + opened / n_cameras}
    zfar = config.render.zfar_m
    for name in order:
        scores = [compare(o, r, zfar) for o, r in zip(outputs[name], outputs["reference"])]
        rows[name].update({k: statistics.median(s[k] for s in scores) for k in scores[0]})
        truth = [label_scores(o, t, zfar) for o, t in zip(outputs[name], truths)]
        rows[name]["vs_raycast"] = {k: statistics.median(s[k] for s in truth) for k in truth[0]}
    result = {"command": " ".join(["glsynth", *sys.argv[1:]]), "root_seed": root_seed,
              "env": env, "cameras": cameras,
              "note": "time_per_sample_s = median render + environment opening / cameras "
                      "per environment; vs_raycast: labels and depth against an Embree ray "
                      "cast of the reference preset's scene",
              "presets": {p: rows[p] for p in presets}}
    atomic_write_json(out / "quality.json", result)
    atomic_write_bytes(out / "quality.md", quality_table(result).encode())
    plot_trade_curve(result, out / "quality.png")
    return result


def quality_table(result: dict) -> str:
    head = ("| preset | size | msaa | textures | damage px | octaves | segments | shadow map "
            "| time/sample | PSNR | SSIM | component agree | damage agree | depth rel err "
            "| area err |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    lines = [f"| {name} | {r['width']}x{r['height']} | {r['msaa']} | {r['texture_size']} | "
             f"{r['damage_resolution']} | {r['octaves']} | {r['cylinder_segments']} | "
             f"{r['shadow_map_px'] or 'off'} | "
             f"{r['time_per_sample_s']:.3f} s | {r['psnr_db']:.1f} dB | {r['ssim']:.3f} | "
             f"{100 * r['component_agreement']:.2f} % | {100 * r['damage_agreement']:.2f} % | "
             f"{r['depth_median_rel_error']:.1e} | {r['damaged_area_error_pp']:.3f} pp |"
             for name, r in result["presets"].items()]
    truth = ("\nAgainst the Embree ray cast of the reference scene (pixel centres, nearest "
             "texel of the damage masks):\n\n| preset | component agree | damage agree "
             "| depth rel err | area err |\n|---|---|---|---|---|\n")
    truth += "\n".join(
        f"| {name} | {100 * t['component_agreement']:.2f} % | "
        f"{100 * t['damage_agreement']:.2f} % | {t['depth_median_rel_error']:.1e} | "
        f"{t['damaged_area_error_pp']:.3f} pp |"
        for name, t in ((n, r["vs_raycast"]) for n, r in result["presets"].items()))
    return head + "\n".join(lines) + "\n" + truth + "\n"


def plot_trade_curve(result: dict, path: Path) -> None:
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    names = list(result["presets"])
    rows = [result["presets"][n] for n in names]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    x = [r["time_per_sample_s"] for r in rows]
    # The reference against itself has no finite PSNR: left out of the colour panel.
    colour = [(n, xi, r["psnr_db"]) for n, xi, r in zip(names, x, rows) if r["psnr_db"] < 99]
    a.plot([c[1] for c in colour], [c[2] for c in colour], "o-")
    for name, xi, psnr in colour:
        a.annotate(name, (xi, psnr), textcoords="offset points", xytext=(4, 4))
    b.plot(x, [100 * r["vs_raycast"]["component_agreement"] for r in rows], "o-",
           label="components")
    b.plot(x, [100 * r["vs_raycast"]["damage_agreement"] for r in rows], "s-", label="damage")
    for name, xi, r in zip(names, x, rows):
        b.annotate(name, (xi, 100 * r["vs_raycast"]["component_agreement"]),
                   textcoords="offset points", xytext=(4, 4))
    a.set_xlabel("time per sample [s]"), a.set_ylabel("colour PSNR vs reference [dB]")
    b.set_xlabel("time per sample [s]"), b.set_ylabel("label agreement vs ray cast [%]")
    b.legend()
    fig.suptitle("glsynth quality presets: speed against accuracy")
    save_figure(fig, path)
