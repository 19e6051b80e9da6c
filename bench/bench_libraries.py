"""Code glsynth writes itself against maintained libraries that do the same: speed, agreement
and install weight, to decide whether to adopt them (docs/design.md, "Libraries weighed").

    .venv/bin/python -m pip install kornia torchmetrics tyro   # for the bench only
    .venv/bin/python bench/bench_libraries.py --data DATASET [--repeats 11] [--threads 1]

- Augmentation (model/augment.py) against kornia: the per-image Gaussian blur against
  kornia.filters.gaussian_blur2d, and the JPEG round trip against
  kornia.enhance.jpeg_codec_differentiable, both codecs measured against OpenCV's libjpeg
  round trip; on a batch of 8 views of DATASET at the 480x270 training size.
- Confusion matrices and IoU (model/metrics.py) against torchmetrics, on the component
  (8 classes) and damage (3 classes) maps of the same views at 640x360, with a prediction
  that is the truth moved by (8, 4) px: errors along every boundary, as a network makes.
- Command-line options from a dataclass (glsynth/core/options.py) against tyro, on
  TrainSettings: import and parse times and what the parsed settings hold.

DATASET is any glsynth dataset (glsynth generate). CPU, one torch thread unless --threads;
times are medians (and minima) of --repeats calls. Writes bench/results/libraries.json.
"""

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import summary, time_calls, write_results  # noqa: E402
from glsynth.model import augment  # noqa: E402
from glsynth.model.data import load_image, load_map  # noqa: E402
from glsynth.model.metrics import confusion, segmentation_scores  # noqa: E402
from glsynth.model.settings import AUGMENTATIONS, CLASS_NAMES, TrainSettings  # noqa: E402

from glsynth.data.dataset import RUN_FILE  # noqa: E402
from glsynth.data.tokaido import read_manifest  # noqa: E402

IMAGE_SIZE = (480, 270)
MAP_SIZE = (640, 360)
BATCH = 8
SHIFT_PX = (8, 4)
PACKAGES = {"kornia": ("kornia", "kornia_rs"), "torchmetrics": ("torchmetrics",
                                                               "lightning_utilities"),
            "tyro": ("tyro", "typeguard", "docstring_parser")}
"""The folders each library adds to site-packages (itself and what it pulls in here)."""


def views(data: Path) -> list:
    rows = read_manifest(data, "files_train.csv") + read_manifest(data, "files_test.csv")
    if len(rows) < BATCH:
        sys.exit(f"--data {data}: {len(rows)} views, the bench needs {BATCH}")
    return rows[:BATCH]


def timed(fn, repeats: int) -> dict:
    return summary(time_calls(fn, repeats))


def levels(a: torch.Tensor, b: torch.Tensor) -> dict:
    """Differences of two [0, 1] images in 8-bit levels, and the PSNR of one against the
    other."""
    d = (a.double() - b.double()).abs() * 255
    mse = float((d ** 2).mean())
    return {"mean_levels": round(float(d.mean()), 4), "max_levels": round(float(d.max()), 3),
            "psnr_db": round(10 * math.log10(255 ** 2 / mse), 2) if mse else None}


def opencv_jpeg(images: torch.Tensor, quality: torch.Tensor) -> torch.Tensor:
    """libjpeg's round trip (OpenCV: 4:2:0, the IJG tables, its default decoder)."""
    out = []
    for image, q in zip(images, quality):
        bgr = (image.permute(1, 2, 0).numpy()[..., ::-1] * 255).round().astype(np.uint8)
        ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(q)])
        decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)[..., ::-1].astype(np.float32) / 255
        out.append(torch.from_numpy(decoded.copy()).permute(2, 0, 1))
    return torch.stack(out)


def weigh_augment(data: Path, repeats: int) -> dict:
    import kornia

    images = torch.stack([load_image(data / r.image, IMAGE_SIZE) for r in views(data)])
    sigma = torch.linspace(*augment.BLUR_SIGMA_PX, BATCH)
    side = 2 * max(1, math.ceil(3 * float(sigma.max()))) + 1  # augment.gaussian_blur's kernel
    ours = augment.gaussian_blur(images, sigma)
    theirs = kornia.filters.gaussian_blur2d(images, (side, side), torch.stack([sigma] * 2, 1),
                                            border_type="replicate")
    blur = {"sigma_px": [round(float(s), 3) for s in sigma], "kernel_px": side,
            "glsynth": timed(lambda: augment.gaussian_blur(images, sigma), repeats),
            "kornia": timed(lambda: kornia.filters.gaussian_blur2d(
                images, (side, side), torch.stack([sigma] * 2, 1), border_type="replicate"),
                repeats),
            "kornia_against_glsynth": levels(theirs, ours)}
    quality = torch.linspace(*augment.JPEG_QUALITY, BATCH).round()
    reference = opencv_jpeg(images, quality)
    ours = augment.jpeg(images, quality)
    theirs = kornia.enhance.jpeg_codec_differentiable(images, quality).clamp(0, 1)
    jpeg = {"quality": quality.tolist(),
            "glsynth": timed(lambda: augment.jpeg(images, quality), repeats),
            "kornia": timed(lambda: kornia.enhance.jpeg_codec_differentiable(images, quality),
                            repeats),
            "opencv_libjpeg": timed(lambda: opencv_jpeg(images, quality), repeats),
            "glsynth_against_libjpeg": levels(ours, reference),
            "kornia_against_libjpeg": levels(theirs, reference),
            "input_against_libjpeg": levels(images, reference)}
    return {"images": f"{BATCH} x 3 x {IMAGE_SIZE[1]} x {IMAGE_SIZE[0]} float32",
            "threads": torch.get_num_threads(), "blur": blur, "jpeg": jpeg}


def prediction_maps(data: Path, task: str) -> tuple[np.ndarray, np.ndarray]:
    """(truth, prediction) of the views, (8, 360, 640) uint8: the prediction is the truth
    moved by SHIFT_PX, ids 1..K everywhere (a network predicts no 0)."""
    truth = np.stack([load_map(data / getattr(r, task), MAP_SIZE) for r in views(data)])
    moved = np.roll(truth, SHIFT_PX[::-1], axis=(1, 2))
    return truth, np.where(moved > 0, moved, 1).astype(np.uint8)


def weigh_task(data: Path, task: str, repeats: int) -> dict:
    from torchmetrics.functional.classification import (
        multiclass_confusion_matrix,
        multiclass_jaccard_index,
    )

    names = CLASS_NAMES[task]
    n = len(names)
    truth, predicted = prediction_maps(data, task)
    t, p = torch.from_numpy(truth).long(), torch.from_numpy(predicted).long()

    def ours() -> tuple[np.ndarray, dict]:
        matrix = confusion(truth, predicted, n)
        return matrix, segmentation_scores(matrix, names)

    # ids 1..K with 0 ignored: K + 1 classes, row and column 0 dropped.
    kw = dict(num_classes=n + 1, ignore_index=0)

    def their_confusion(check: bool = True) -> torch.Tensor:
        return multiclass_confusion_matrix(p, t, validate_args=check, **kw)[1:, 1:]

    def theirs(check: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
        return (their_confusion(check),
                multiclass_jaccard_index(p, t, average="none", validate_args=check, **kw)[1:])

    matrix, scores = ours()
    their_matrix, their_iou = theirs()
    iou = [scores["per_class"][c]["iou"] for c in names]
    return {"classes": n, "maps": f"{BATCH} x {MAP_SIZE[1]} x {MAP_SIZE[0]} uint8",
            "confusion_only": {
                "glsynth": timed(lambda: confusion(truth, predicted, n), repeats),
                "torchmetrics": timed(their_confusion, repeats),
                "torchmetrics_unchecked": timed(lambda: their_confusion(False), repeats)},
            "confusion_and_iou": {
                "glsynth": timed(ours, repeats), "torchmetrics": timed(theirs, repeats),
                "torchmetrics_unchecked": timed(lambda: theirs(False), repeats)},
            "same_confusion": bool(np.array_equal(matrix, their_matrix.numpy())),
            "iou_glsynth": iou, "iou_torchmetrics": [round(float(v), 6) for v in their_iou],
            "iou_max_difference": max((abs(a - float(b)) for a, b in zip(iou, their_iou)
                                       if a is not None), default=None),
            "mean_iou_glsynth": scores["mean"]["iou"],
            "mean_iou_torchmetrics_macro": float(multiclass_jaccard_index(
                p, t, average="macro", **kw))}


def import_seconds(module: str) -> float:
    """Median of 5 fresh interpreters' time to import ``module`` (after argparse, which
    both need)."""
    code = ("import argparse, time; t = time.perf_counter(); import " + module +
            "; print(time.perf_counter() - t)")
    times = [float(subprocess.run([sys.executable, "-c", code], capture_output=True,
                                  text=True, check=True).stdout) for _ in range(5)]
    return sorted(times)[2]


TRAIN_ARGS = {"glsynth": ["--task", "component", "--data", "d", "--image-size", "480x270",
                          "--schedule", "1e-3:2", "--augment", "all"],
              "tyro": ["--task", "component", "--data", "d", "--image-size", "480", "270",
                       "--schedule", "1e-3", "2", "--augment", *AUGMENTATIONS]}
"""One train command line in each library's spelling: tyro reads a tuple[int, int] as two
words and does not know the fields' parse functions (WxH, LR:EPOCHS, all|none, a resolved
folder)."""


def weigh_options(repeats: int) -> dict:
    import tyro

    from glsynth.core.options import add_options, from_options

    def ours() -> TrainSettings:
        parser = argparse.ArgumentParser()
        add_options(parser, TrainSettings)
        return from_options(TrainSettings, parser.parse_args(TRAIN_ARGS["glsynth"]))

    def theirs() -> TrainSettings:
        return tyro.cli(TrainSettings, args=TRAIN_ARGS["tyro"])

    mine, other = ours(), theirs()
    return {"train_args": TRAIN_ARGS,
            "import_s": {"glsynth.core.options": import_seconds("glsynth.core.options"),
                         "tyro": import_seconds("tyro")},
            "parser_and_parse": {"glsynth": timed(ours, repeats), "tyro": timed(theirs, repeats)},
            "glsynth_settings": repr(mine), "tyro_settings": repr(other),
            "same_settings": mine == other}


def weights() -> dict:
    """MiB each library adds to site-packages (with what it pulls in here)."""
    import importlib.util

    out = {}
    for library, folders in PACKAGES.items():
        total = 0
        for name in folders:
            spec = importlib.util.find_spec(name)
            root = Path(spec.origin).parent
            total += sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
        out[library] = {"packages": list(folders), "mib": round(total / 2 ** 20, 1)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--data", required=True, type=Path)
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (1: numpy's count, and steadier on a shared CPU)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if not (args.data / "files_train.csv").is_file():
        sys.exit(f"--data {args.data}: no dataset there (glsynth generate --out DIR)")
    import importlib.metadata as meta

    versions = {p: meta.version(p) for p in ("torch", "kornia", "torchmetrics", "tyro")}
    run = json.loads((args.data / RUN_FILE).read_text()) if (args.data / RUN_FILE).is_file() \
        else {}
    write_results("libraries", {
        "versions": versions, "install_mib": weights(),
        "dataset": {"root_seed": run.get("root_seed"), "config_sha256": run.get("config_sha256"),
                    "views": [r.image for r in views(args.data)]},
        "augment": weigh_augment(args.data, args.repeats),
        "metrics": {task: weigh_task(args.data, task, args.repeats) for task in CLASS_NAMES},
        "options": weigh_options(args.repeats)})


if __name__ == "__main__":
    main()
