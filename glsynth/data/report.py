"""Pictures of a generated dataset for people: a contact sheet of samples with label overlays."""

from pathlib import Path

import numpy as np
from PIL import Image

from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, depth_rgb, overlay
from glsynth.data.tokaido import decode_depth, read_manifest


def contact_sheet(root: Path, samples: int = 6, width: int = 320) -> np.ndarray:
    """Rows of (image | components | damage | depth) for up to ``samples`` evenly spread
    training and test views."""
    records = read_manifest(root, "files_train.csv") + read_manifest(root, "files_test.csv")
    if not records:
        return np.zeros((8, 4 * width, 3), np.uint8)
    picks = np.linspace(0, len(records) - 1, min(samples, len(records))).round().astype(int)
    height = width * 9 // 16
    rows = []
    for i in picks:
        r = records[i]

        def load(rel: str, mode: str | None = None) -> np.ndarray:
            im = Image.open(root / rel)
            return np.asarray(im.convert(mode) if mode else im)

        image = np.asarray(Image.fromarray(load(r.image, "RGB")).resize((width, height)))
        size = (width, height)
        comp = np.asarray(Image.fromarray(load(r.component)).resize(size, Image.NEAREST))
        dmg = np.asarray(Image.fromarray(load(r.damage)).resize(size, Image.NEAREST))
        depth = decode_depth(np.asarray(Image.fromarray(load(r.depth)).resize(size,
                                                                            Image.NEAREST)))
        rows.append(np.concatenate([image, overlay(image, comp, COMPONENT_RGB, 0.55),
                                    overlay(image, dmg, DAMAGE_RGB, 0.8, skip=(1,)),
                                    depth_rgb(depth)], axis=1))
    return np.concatenate(rows, axis=0)
