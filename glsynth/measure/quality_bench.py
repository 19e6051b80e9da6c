"""``glsynth bench quality``: the quality presets (glsynth/data/quality.py) measured, speed
against accuracy. Colour is scored against Blender Cycles or the 'reference' preset, labels and
depth against an Embree ray cast of the reference scene.
"""

import dataclasses
import functools
import shutil
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from glsynth.core.config import Config
from glsynth.core.fileio import png_bytes
from glsynth.core.images import nearest_resize
from glsynth.core.labels import Component
from glsynth.data.quality import QUALITY, apply_quality
from glsynth.data.tokaido import IMAGE_SIZE
from glsynth.world.lighting import LUMINANCE

_FULL_SIZE = "x".join(map(str, IMAGE_SIZE))


def spread_cameras(total: int, count: int) -> list[int]:
    """``count`` camera indices spread evenly over an environment's ``total`` cameras."""
    return sorted({round(i * (total - 1) / max(1, count - 1)) for i in range(count)})


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


def colour_scores(image: np.ndarray, reference: np.ndarray, component: np.ndarray) -> dict:
    """Colour of one image against a reference of the same size: PSNR, SSIM, mean CIEDE2000,
    and mean CIEDE2000 inside the regions that matter: columns, the deck seen from below (slab
    and beam pixels), and shadowed areas (reference luminance below half its median over
    geometry)."""
    from skimage.color import deltaE_ciede2000, rgb2lab
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    identical = np.array_equal(reference, image)  # PSNR is infinite: report 99 dB
    psnr = 99.0 if identical else peak_signal_noise_ratio(reference, image, data_range=255)
    delta = deltaE_ciede2000(rgb2lab(reference), rgb2lab(image))
    luminance = reference.astype(np.float64) @ LUMINANCE
    geometry = component != Component.NONBRIDGE
    dark = luminance < 0.5 * np.median(luminance[geometry]) if geometry.any() else geometry
    regions = {"columns": component == Component.COLUMN,
               "deck_underside": (component == Component.SLAB) | (component == Component.BEAM),
               "shadowed": dark}
    return {"psnr_db": float(min(psnr, 99.0)),
            "ssim": float(structural_similarity(reference, image, channel_axis=2,
                                                data_range=255)),
            "ciede2000": float(delta.mean()),
            **{f"ciede2000_{name}": float(delta[m].mean()) if m.any() else None
               for name, m in regions.items()}}


def area_resize(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Colour to (width, height) by pixel-area averaging (OpenCV INTER_AREA)."""
    import cv2

    if image.shape[1::-1] == tuple(size):
        return image
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def _median_scores(scores: list[dict]) -> dict:
    """Per key, the median over the views that have it (a region may be absent from a view);
    None where no view has it."""
    out = {}
    for k in scores[0]:
        values = [s[k] for s in scores if s[k] is not None]
        out[k] = statistics.median(values) if values else None
    return out


@dataclass
class _PresetRun:
    renders: list
    placements: list
    row: dict


def _run_preset(config: Config, name: str, root_seed: int, env: int, cameras: list[int],
                keep_scene: bool) -> tuple[_PresetRun, dict | None]:
    from glsynth.render.raycast import ray_cast
    from glsynth.render.view import EnvironmentView

    cfg = apply_quality(config, name)
    t0 = time.perf_counter()
    view = EnvironmentView.open(cfg, root_seed, env)
    opened = time.perf_counter() - t0
    renders, times, placements = [], [], []
    scene = None
    try:
        view.render(cameras[0], photo=False)  # warm-up: shaders, first texture use
        for index in cameras:
            t = time.perf_counter()
            # The renderer against its references: the camera model is not measured here.
            placement, output = view.render(index, photo=False)
            times.append(time.perf_counter() - t)
            renders.append(output)
            placements.append(placement)
        if keep_scene:
            parts = [p for p in view.environment.parts if p.name in view.scene.parts]
            # Built once here: the truths and every Cycles run read them (a deferred damage
            # material would be built again on each read).
            materials = dict(view.dressing.materials)
            scene = {"parts": parts, "materials": materials,
                     "lighting": view.lighting,
                     "truths": [ray_cast(view.environment.parts, materials, p.camera)
                                for p in placements]}
    finally:
        view.renderer.release()
    render_s = statistics.median(times)
    per_sample = render_s + opened / cfg.cameras.total
    row = {**dataclasses.asdict(QUALITY[name]), "width": cfg.render.width,
           "height": cfg.render.height, "render_s": render_s, "open_s": opened,
           "time_per_sample_s": per_sample}
    return _PresetRun(renders, placements, row), scene


def _cycles_renders(scene: dict, placements: list, samples: int, seed_offset: int,
                    size: tuple[int, int], root_seed: int, env: int, work: Path,
                    blender: str) -> tuple[list[np.ndarray], list[float]]:
    """Cycles images of the reference scene's views at ``size``, tone-mapped as glsynth's."""
    from glsynth.render.cycles import cycles_seed, display, render_linear

    cams = [dataclasses.replace(p.camera, width=size[0], height=size[1]) for p in placements]
    seeds = [cycles_seed(root_seed, env, p.index) + seed_offset for p in placements]
    result = render_linear(scene["parts"], scene["materials"], scene["lighting"], cams, seeds,
                           samples, work, blender)
    return ([display(x, scene["lighting"]) for x in result.linear],
            result.colour_s)


def _cycles_timing(scene: dict, placement, root_seed: int, env: int, work: Path,
                   blender: str) -> dict:
    """Cycles' time for one full-size (Tokaido) view as fixed + per sample: the view at 1, 1 and 4
    samples in one process (the first render loads the scene; the next two are timed)."""
    from glsynth.render.cycles import cycles_seed, render_linear

    cam = dataclasses.replace(placement.camera, width=IMAGE_SIZE[0], height=IMAGE_SIZE[1])
    seed = cycles_seed(root_seed, env, placement.index)
    result = render_linear(scene["parts"], scene["materials"], scene["lighting"],
                           [cam] * 3, [seed] * 3, [1, 1, 4], work, blender)
    _, one, four = result.colour_s
    per_sample = max(four - one, 0.0) / 3
    return {"fixed_s": one - per_sample, "per_sample_s": per_sample,
            "first_render_s": result.colour_s[0], "import_s": result.import_s}


@dataclass
class _Reference:
    """The colour every preset is scored against, at the comparison size."""

    name: str
    images: list[np.ndarray]
    render_s: list[float] = dataclasses.field(default_factory=list)
    """Cycles' times at the comparison size (none for glsynth's reference preset)."""
    noise_floor: dict | None = None
    cycles_1080p_timing: dict | None = None
    cycles_rows: dict = dataclasses.field(default_factory=dict)
    """Cycles at each sample count of the time axis, scored as the presets are."""


def _median_colour_scores(images: list[np.ndarray], reference: list[np.ndarray],
                          components: list[np.ndarray]) -> dict:
    return _median_scores([colour_scores(i, r, c)
                           for i, r, c in zip(images, reference, components)])


def _run_presets(config: Config, presets: list[str], root_seed: int, env: int,
                 cameras: list[int]) -> tuple[dict[str, _PresetRun], dict]:
    """Each preset's renders, the 'reference' preset's first; its scene (with the ray-cast
    truths) is returned for scoring and for Cycles."""
    runs: dict[str, _PresetRun] = {}
    scene = None
    for name in ["reference"] + [p for p in presets if p != "reference"]:
        runs[name], kept = _run_preset(config, name, root_seed, env, cameras,
                                       keep_scene=name == "reference")
        scene = kept or scene
    return runs, scene


def _cycles_reference(scene: dict, placements: list, components: list[np.ndarray],
                      size: tuple[int, int], root_seed: int, env: int, out: Path, blender: str,
                      reference_samples: int, cycles_samples: tuple[int, ...]) -> _Reference:
    """Cycles at ``reference_samples`` as the reference, rendered twice with different seeds
    (its noise floor), and Cycles at each of ``cycles_samples`` scored against it."""
    from glsynth.core.fileio import atomic_write_bytes

    work = out / "cycles_work"
    render = functools.partial(_cycles_renders, scene, placements, size=size,
                               root_seed=root_seed, env=env, work=work, blender=blender)
    images, times = render(reference_samples, 0)
    second, _ = render(reference_samples, 1_000_003)
    reference = _Reference(
        name=f"Cycles {reference_samples} samples", images=images, render_s=times,
        noise_floor=_median_colour_scores(second, images, components),
        cycles_1080p_timing=_cycles_timing(scene, placements[0], root_seed, env, work, blender))
    timing = reference.cycles_1080p_timing
    for n in cycles_samples:
        noisy, times = render(n, 2_000_006)
        reference.cycles_rows[str(n)] = {
            "samples": n, "render_s_at_size": statistics.median(times),
            "time_per_sample_s": timing["fixed_s"] + timing["per_sample_s"] * n,
            **_median_colour_scores(noisy, images, components)}
        atomic_write_bytes(out / f"cycles_{n}spp.png", png_bytes(noisy[0]))
    shutil.rmtree(work, ignore_errors=True)
    atomic_write_bytes(out / "cycles_reference.png", png_bytes(images[0]))
    return reference


def _preset_row(run: _PresetRun, images: list[np.ndarray], reference: _Reference,
                components: list[np.ndarray], truths: list, zfar: float) -> dict:
    """A preset's knobs and times, its colour ``images`` (at the comparison size) scored
    against the reference, and its labels and depth against the ray cast."""
    return {**run.row, **_median_colour_scores(images, reference.images, components),
            "vs_raycast": _median_scores([label_scores(o, t, zfar)
                                          for o, t in zip(run.renders, truths)])}


def _side_by_side(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The image, the reference and their difference x 4."""
    diff = np.clip(np.abs(image.astype(int) - reference.astype(int)) * 4, 0, 255)
    return np.concatenate([image, reference, diff.astype(np.uint8)], axis=1)


def bench_quality(config: Config, root_seed: int, env: int, cameras: list[int], out: Path,
                  presets: list[str] | None = None, blender: str | None = None,
                  size: tuple[int, int] = (480, 270), reference_samples: int = 128,
                  cycles_samples: tuple[int, ...] = (1, 4, 16, 64)) -> dict:
    """Render the same views under each preset and time them. Colour is scored at ``size``
    against Cycles at ``reference_samples`` when ``blender`` is given (else against the
    'reference' preset); labels and depth against an Embree ray cast of the reference
    preset's scene. With Blender, the reference is rendered twice with different seeds (its
    noise floor) and Cycles at each of ``cycles_samples`` joins the time axis.
    side_by_side.png: the first view under the 'default' preset (or the first preset run),
    the reference and their difference x 4."""
    from glsynth.core.fileio import atomic_write_bytes, atomic_write_json

    presets = presets or list(QUALITY)
    runs, scene = _run_presets(config, presets, root_seed, env, cameras)
    renders = runs["reference"].renders
    components = [nearest_resize(o.component, size[::-1]) for o in renders]
    if blender is None:
        reference = _Reference(name="glsynth 'reference' preset",
                               images=[area_resize(o.color, size) for o in renders])
    else:
        reference = _cycles_reference(scene, runs["reference"].placements, components, size,
                                      root_seed, env, out, blender, reference_samples,
                                      cycles_samples)
    rows = {}
    shown = "default" if "default" in presets else presets[0]
    for name in presets:
        images = [area_resize(o.color, size) for o in runs[name].renders]
        rows[name] = _preset_row(runs[name], images, reference, components, scene["truths"],
                                 config.render.zfar_m)
        if name == shown:
            atomic_write_bytes(out / "side_by_side.png",
                               png_bytes(_side_by_side(images[0], reference.images[0])))
    result = {"command": " ".join(["glsynth", *sys.argv[1:]]), "root_seed": root_seed,
              "env": env, "cameras": cameras, "size": list(size),
              "reference": reference.name, "reference_samples": reference_samples,
              "reference_render_s_at_size": (statistics.median(reference.render_s)
                                             if reference.render_s else None),
              "noise_floor": reference.noise_floor,
              "cycles_1080p_timing": reference.cycles_1080p_timing,
              "lighting": dataclasses.asdict(scene["lighting"]),
              "render_knobs": {k: getattr(getattr(config, s), k) for s, k in LIGHTING_KNOBS},
              "note": "time_per_sample_s: glsynth = median render at the preset's own size + "
                      "environment opening / cameras per environment; Cycles = fixed + "
                      f"per-sample time of a {_FULL_SIZE} render of the first view, measured at 1 "
                      "and 4 samples with the scene already loaded. Colour compared "
                      "at the comparison size (glsynth area-averaged down to it); "
                      "vs_raycast: labels and depth against an Embree ray cast of the "
                      "reference preset's scene",
              "presets": rows, "cycles": reference.cycles_rows}
    atomic_write_json(out / "quality.json", result)
    atomic_write_bytes(out / "quality.md", quality_table(result).encode())
    plot_trade_curve(result, out / "quality.png")
    return result


LIGHTING_KNOBS = (("lighting", "sky"), ("render", "ao_radius_m"), ("render", "ao_samples"))
"""The lighting settings a quality run records beside its numbers, as (section, key) (the
presets set shadows, sky maps and ao: each row has its own)."""


def _fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def quality_table(result: dict) -> str:
    lines = [f"Colour against {result['reference']} at {result['size'][0]}x"
             f"{result['size'][1]}; lighting knobs {result['render_knobs']}.", "",
             "| renderer | size | msaa | textures | damage px | shadow map | sky maps | ao "
             "| time/sample | PSNR | SSIM | CIEDE2000 | columns | deck underside | shadowed |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in result["presets"].items():
        lines.append(
            f"| glsynth {name} | {r['width']}x{r['height']} | {r['msaa']} | "
            f"{r['texture_size']} | {r['damage_resolution']} | {r['shadow_map_px'] or 'off'} "
            f"| {r['sky_visibility_maps']} | {r['ao']} "
            f"| {r['time_per_sample_s']:.3f} s | {r['psnr_db']:.1f} dB | {r['ssim']:.3f} | "
            f"{r['ciede2000']:.2f} | {_fmt(r['ciede2000_columns'], '.2f')} | "
            f"{_fmt(r['ciede2000_deck_underside'], '.2f')} | "
            f"{_fmt(r['ciede2000_shadowed'], '.2f')} |")
    for n, r in result["cycles"].items():
        lines.append(
            f"| Cycles {n} spp | {_FULL_SIZE} | - | - | - | - | - | - | "
            f"{r['time_per_sample_s']:.1f} s | {r['psnr_db']:.1f} dB | "
            f"{r['ssim']:.3f} | {r['ciede2000']:.2f} | {_fmt(r['ciede2000_columns'], '.2f')} "
            f"| {_fmt(r['ciede2000_deck_underside'], '.2f')} | "
            f"{_fmt(r['ciede2000_shadowed'], '.2f')} |")
    if result["noise_floor"]:
        f = result["noise_floor"]
        lines += ["", f"Noise floor (the reference against itself, another seed): CIEDE2000 "
                  f"{f['ciede2000']:.2f}, PSNR {f['psnr_db']:.1f} dB, SSIM {f['ssim']:.3f}."]
    truth = ["", "Labels and depth against the Embree ray cast of the reference scene (pixel "
             "centres, nearest texel of the damage masks):", "",
             "| preset | component agree | damage agree | depth rel err | area err |",
             "|---|---|---|---|---|"]
    truth += [f"| {name} | {100 * t['component_agreement']:.2f} % | "
              f"{100 * t['damage_agreement']:.2f} % | {t['depth_median_rel_error']:.1e} | "
              f"{t['damaged_area_error_pp']:.3f} pp |"
              for name, t in ((n, r["vs_raycast"]) for n, r in result["presets"].items())]
    return "\n".join(lines + truth) + "\n"


def plot_trade_curve(result: dict, path: Path) -> None:
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5), layout="constrained")
    names = list(result["presets"])
    rows = [result["presets"][n] for n in names]
    x = [r["time_per_sample_s"] for r in rows]
    a.plot(x, [r["ciede2000"] for r in rows], "o-", label="glsynth presets")
    for i, (name, xi, r) in enumerate(zip(names, x, rows)):
        # Alternate above and below: presets of nearly equal time and error would overprint.
        a.annotate(name, (xi, r["ciede2000"]), textcoords="offset points",
                   xytext=(4, 4 if i % 2 else -12))
    if result["cycles"]:
        cyc = list(result["cycles"].values())
        a.plot([c["time_per_sample_s"] for c in cyc], [c["ciede2000"] for c in cyc], "s-",
               label="Cycles")
        for c in cyc:
            a.annotate(f"{c['samples']} spp", (c["time_per_sample_s"], c["ciede2000"]),
                       textcoords="offset points", xytext=(4, 4))
    if result["noise_floor"]:
        a.axhline(result["noise_floor"]["ciede2000"], color="grey", ls=":",
                  label="reference noise floor")
    a.set_xscale("log")
    a.set_xlabel(f"time per {_FULL_SIZE} sample [s]")
    a.set_ylabel(f"mean CIEDE2000 vs {result['reference']}")
    a.legend()
    b.plot(x, [100 * r["vs_raycast"]["component_agreement"] for r in rows], "o-",
           label="components")
    b.plot(x, [100 * r["vs_raycast"]["damage_agreement"] for r in rows], "s-", label="damage")
    for i, (name, xi, r) in enumerate(zip(names, x, rows)):
        b.annotate(name, (xi, 100 * r["vs_raycast"]["component_agreement"]),
                   textcoords="offset points", xytext=(4, 4 if i % 2 else -12))
    b.set_xlabel("time per sample [s]"), b.set_ylabel("label agreement vs ray cast [%]")
    b.legend()
    fig.suptitle("speed against accuracy: glsynth presets and Cycles")
    save_figure(fig, path)
