"""Crack masks as the sim-to-real networks see them: glsynth datasets beside real folders.

    .venv/bin/python bench/bench_crack_masks.py --synthetic DATASET... --real FOLDER...

Each glsynth dataset is read as `glsynth bench sim2real` reads it (crack = crack-width map >
0, the image brought down to the map's 640x360) and each real folder (images/ and masks/) as
is. Per set: the crack pixels' share of a view (mean over images); the crack's width in
pixels, twice the distance to the background at each pixel of the mask's skeleton (a one-pixel
line reads 2), median and 90th percentile over all skeleton pixels; the median over images of
the crack pixels' mean luma over the rest's (Rec. 601 of the sRGB bytes); and, against the
concrete just beside the crack (the median luma of a ring RING_PX outside the mask), the
median over images of the crack pixels' median luma, of the mask's edge pixels' (those within
one pixel of the background), and the share of crack pixels darker than DARK of the ring: how
far a mask reaches past the crack's dark core. Writes bench/results/crack_masks.json.
"""

import argparse
from pathlib import Path

import cv2
import numpy as np
from common import LUMA, write_results
from skimage.morphology import skeletonize

from glsynth.data.crack_folders import CrackImage, read_real_folder, read_synthetic

RING_PX = (4.0, 8.0)
"""The ring of background beside a crack: pixels this far from the mask (exclusive, inclusive)."""
DARK = 0.85
"""A crack pixel counts as dark below this share of the ring's luma."""


def local_contrast(crack: np.ndarray, inside: np.ndarray, luma: np.ndarray
                   ) -> tuple[float, float, float] | None:
    """(crack pixels' median luma, the mask edge's median luma, the share of crack pixels
    darker than DARK) over the ring's median luma; ``inside``: each crack pixel's distance to
    the background; None without a ring."""
    outside = cv2.distanceTransform((~crack).astype(np.uint8), cv2.DIST_L2, 5)
    ring = (outside > RING_PX[0]) & (outside <= RING_PX[1])
    if not ring.any():
        return None
    beside = max(float(np.median(luma[ring])), 1e-6)
    edge = crack & (inside <= 1.0)
    return (float(np.median(luma[crack])) / beside, float(np.median(luma[edge])) / beside,
            float(np.mean(luma[crack] < DARK * beside)))


def _median(values: list[float]) -> float | None:
    return round(float(np.median(values)), 3) if values else None


def mask_stats(images: list[CrackImage]) -> dict:
    """The statistics of one set (the module's docstring)."""
    widths, contrast, local = [], [], []
    for image in images:
        if not image.crack.any():
            continue
        crack = image.crack.astype(np.uint8)
        distance = cv2.distanceTransform(crack, cv2.DIST_L2, 5)
        widths.append(2.0 * distance[skeletonize(image.crack)])
        luma = image.rgb.astype(float) @ LUMA
        if (~image.crack).any():
            contrast.append(luma[image.crack].mean() / max(luma[~image.crack].mean(), 1e-6))
        beside = local_contrast(image.crack, distance, luma)
        if beside is not None:
            local.append(beside)
    every = np.concatenate(widths) if widths else np.zeros(0)
    return {"images": len(images), "images_without_cracks": len(images) - len(widths),
            "crack_share_pct": round(100 * float(np.mean([i.crack.mean() for i in images])), 3),
            "width_px_median": round(float(np.median(every)), 2) if every.size else None,
            "width_px_p90": round(float(np.percentile(every, 90)), 2) if every.size else None,
            "crack_over_background_luma": _median(contrast),
            "crack_over_beside_luma": _median([c for c, _, _ in local]),
            "edge_over_beside_luma": _median([e for _, e, _ in local]),
            "crack_darker_share": _median([d for _, _, d in local])}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--synthetic", nargs="*", default=[], help="glsynth datasets")
    p.add_argument("--real", nargs="*", default=[], help="folders with images/ and masks/")
    args = p.parse_args()
    results = {}
    for folder, read in [*((s, read_synthetic) for s in args.synthetic),
                         *((r, read_real_folder) for r in args.real)]:
        name = Path(folder).resolve().name  # as glsynth bench sim2real names its networks
        results[name] = mask_stats(read(folder))
        print(name, results[name], flush=True)
    write_results("crack_masks", results)


if __name__ == "__main__":
    main()
