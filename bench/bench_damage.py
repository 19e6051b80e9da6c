"""Time one full damage texture set (noise, masks, RGB, metallic, normal) and the
speed/quality trade of resolution and octaves.

    .venv/bin/python bench/bench_damage.py [--repeats 3]

Quality of a (resolution, octaves) setting is measured against 2048 px and 8 octaves made
from the same parameters: the fraction of mask pixels that differ after resampling the
reference to the same size (nearest), and the achieved damaged-area error.
"""

import argparse
import dataclasses
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.appearance.damage import (  # noqa: E402
    SEVERITIES,
    compose_rgb,
    damage_maps,
    metallic_map,
    normal_map,
    sample_params,
)
from glsynth.appearance.repository import TextureRepository, generate_repository  # noqa: E402
from glsynth.core.config import DamageConfig  # noqa: E402
from glsynth.core.seeding import Stream, make_rng  # noqa: E402


def full_set(cfg: DamageConfig, severity: str, item: int, images: list[np.ndarray]):
    rng = make_rng(0, 0, Stream.DAMAGE_BANK, item)
    params = sample_params(cfg, severity, rng)
    maps = damage_maps(params, cfg, rng)
    rgb = compose_rgb(maps.mask, *images)
    metal = metallic_map(maps.mask)
    normals = normal_map(maps.displacement_m, cfg.tile_m / cfg.resolution)  # as the bank does
    return params, maps, rgb, metal, normals


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        repo = TextureRepository(generate_repository(tmp, 0, 1, 512), 512)
        results: dict = {}
        reference = {}
        for size in (2048, 1024, 512):
            imgs = [np.tile(repo.image(c, 0), (size // 512 or 1,) * 2 + (1,))[:size, :size]
                    if size >= 512 else repo.image(c, 0)[:size, :size]
                    for c in ("concrete", "concrete", "steel")]
            for octaves in (8, 4, 2, 1) if size == 2048 else (8, 4):
                cfg = dataclasses.replace(DamageConfig(), resolution=size, octaves=octaves)
                times, diffs, area_err = [], [], []
                for s_index, severity in enumerate(SEVERITIES):
                    for rep in range(args.repeats):
                        item = 10 * s_index + rep
                        t0 = time.perf_counter()
                        params, maps, *_ = full_set(cfg, severity, item, imgs)
                        times.append(time.perf_counter() - t0)
                        area_err.append(abs(float((maps.mask != 1).mean()) - params.area))
                        if size == 2048 and octaves == 8:
                            reference[item] = maps.mask
                        else:
                            ref = reference[item][:: 2048 // size, :: 2048 // size]
                            diffs.append(float((ref != maps.mask).mean()))
                results[f"{size}px, {octaves} octaves"] = {
                    "median_s": round(statistics.median(times), 3),
                    "max_s": round(max(times), 3),
                    "max_area_error_pp": round(100 * max(area_err), 4),
                    "mask_pixels_differing_from_2048px_8oct": (
                        round(statistics.median(diffs), 4) if diffs else 0.0)}
    write_results("damage", results)


if __name__ == "__main__":
    main()
