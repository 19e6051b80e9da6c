"""The three trained networks feeding the condition assessment (paper Section 4.7), and its
evaluation on a labelled split: damage scores before and after the RRDR post-processing
(Table 10 against Table 13) and image-wise IoU against damage pixel ratio (Fig. 18).
"""

from pathlib import Path

import numpy as np
import torch
from glsynth.model.data import image_tensor
from glsynth.model.inference import Predictor, load_predictor, resize_map
from glsynth.model.metrics import confusion, segmentation_scores
from glsynth.model.settings import CLASS_NAMES, TASKS

from glsynth.assess.condition import ASSESS_DEFAULTS, AssessSettings, Maps, Photo
from glsynth.core.errors import UserError, named
from glsynth.core.fileio import distinct_stems
from glsynth.core.filters import rrdr
from glsynth.core.images import read_photo


def parse_runs(text: str) -> dict[str, str]:
    """'component=RUN1,damage=RUN2,depth=RUN3' -> {task: run}."""
    runs = {}
    for part in text.split(","):
        task, _, run = part.partition("=")
        if task not in TASKS or not run:
            raise UserError(f"--runs {text!r}: write component=RUN1,damage=RUN2,depth=RUN3")
        runs[task] = run
    missing = set(TASKS) - set(runs)
    if missing:
        raise UserError(f"--runs {text!r}: missing {', '.join(sorted(missing))}; give all "
                        "three trained runs")
    return runs


def load_predictors(runs: dict[str, str], device: str = "auto") -> dict[str, Predictor]:
    predictors = {}
    for task, run in runs.items():
        predictor = load_predictor(run, device)
        if predictor.task != task:
            raise UserError(f"--runs {task}={run}: that run was trained for "
                            f"{predictor.task!r}, not {task!r}")
        predictors[task] = predictor
    return predictors


def predicted_maps(predictors: dict[str, Predictor], path: Path,
                   focal_mm: float | None, sensor_mm: float) -> tuple[np.ndarray, Maps]:
    """Photo and the networks' maps at a third of their input size. The focal length is in
    pixels of the photo; a map pixel spans photo width / map width photo pixels (the photo is
    resized, not cropped)."""
    rgb = read_photo(path)
    inputs: dict[tuple[int, int], torch.Tensor] = {}  # one resize per input size
    outputs = {}
    for task, predictor in predictors.items():
        size = predictor.image_size
        if size not in inputs:
            inputs[size] = image_tensor(rgb, size)[None]
        outputs[task] = predictor(inputs[size])[0].numpy()
    shapes = {v.shape for v in outputs.values()}
    if len(shapes) != 1:
        raise UserError(f"the runs were trained at different image sizes ({shapes}); train "
                        "the three at one --image-size")
    focal_px = None if focal_mm is None else focal_mm / sensor_mm * rgb.shape[1]
    return rgb, Maps(outputs["component"].astype(np.uint8), outputs["damage"].astype(np.uint8),
                     outputs["depth"].astype(np.float32), focal_px,
                     rgb.shape[1] / outputs["component"].shape[1])


def network_photos(predictors: dict[str, Predictor], images: list[str],
                   focals_mm: list[float | None], sensor_mm: float = 36.0) -> list[Photo]:
    """One Photo per image path, with its focal length in mm (None: unknown)."""
    def loader(path: Path, focal_mm: float | None):
        return lambda: predicted_maps(predictors, path, focal_mm, sensor_mm)

    stems = distinct_stems(images)
    return [Photo(stem, loader(Path(p), f)) for stem, p, f in zip(stems, images, focals_mm)]


def evaluate_rrdr(predictors: dict[str, Predictor], root: Path, out: Path,
                  settings: AssessSettings = ASSESS_DEFAULTS, split: str = "test",
                  use_focal: bool = True, sensor_mm: float = 36.0) -> dict:
    """Damage precision/recall/IoU on the split's damage images before and after keeping only
    pixels inside the RRDR of the predicted depth (px/cm with the manifest's focal length, or
    the depth range with use_focal False, as the paper's Table 13 does for real photos)."""
    from glsynth.model.data import TokaidoDataset

    from glsynth.core.fileio import atomic_write_json

    dataset = TokaidoDataset(root, split, "damage",
                             image_size=predictors["damage"].image_size)
    if len(dataset) == 0:
        raise UserError(f"--data {named(root)}: no {split} images with damage in the RRDR")
    before, after = np.zeros((3, 3), np.int64), np.zeros((3, 3), np.int64)
    images = []
    for index, record in enumerate(dataset.items):
        truth = dataset.target(index).numpy()
        photo = read_photo(root / record.image)
        inputs = {size: image_tensor(photo, size)[None]
                  for size in {p.image_size for p in predictors.values()}}
        damage = predictors["damage"](inputs[predictors["damage"].image_size])[0].numpy()
        depth = predictors["depth"](inputs[predictors["depth"].image_size])[0].numpy()
        if depth.shape != truth.shape:
            depth = resize_map(depth.astype(np.float32), truth.shape[::-1])
        # px/cm is the photo's resolution, whatever size the networks saw.
        focal_px = record.focal_mm / sensor_mm * photo.shape[1] if use_focal else None
        reliable = rrdr(depth, focal_px, min_px_per_cm=settings.min_px_per_cm,
                        depth_range_m=settings.depth_range_m)
        m_before = confusion(truth, damage, 3)
        m_after = confusion(np.where(reliable, truth, 0), damage, 3)
        before += m_before
        after += m_after
        labelled = int((truth > 0).sum())
        images.append({"image": record.image,
                       "concrete_pixel_ratio": float((truth == 2).sum() / truth.size),
                       "labelled_pixels": labelled,
                       "concrete_iou_before": _class_iou(m_before, 1),
                       "concrete_iou_after": _class_iou(m_after, 1)})
    result = {"split": split, "images": len(images), "rrdr": "px/cm" if use_focal else
              "depth range", "settings": {"min_px_per_cm": settings.min_px_per_cm,
                                          "depth_range_m": list(settings.depth_range_m)},
              "before": segmentation_scores(before, CLASS_NAMES["damage"]),
              "after": segmentation_scores(after, CLASS_NAMES["damage"]),
              "per_image": images}
    atomic_write_json(out / "rrdr_evaluation.json", result)
    plot_iou_against_ratio(images, out / "fig18_iou_vs_pixel_ratio.png")
    return result


def _class_iou(matrix: np.ndarray, k: int) -> float | None:
    tp = matrix[k, k]
    union = matrix[k, :].sum() + matrix[:, k].sum() - tp
    return float(tp / union) if union else None


def plot_iou_against_ratio(images: list[dict], path: Path) -> None:
    """Fig. 18: image-wise concrete-damage IoU against its pixel ratio, before and after the
    RRDR post-processing, over a histogram of the ratios."""
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    ratio = np.array([r["concrete_pixel_ratio"] for r in images])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    bins = np.linspace(0, max(0.05, float(ratio.max(initial=0)) * 1.05), 11)
    for ax, key, title in ((axes[0], "concrete_iou_before", "(a) before"),
                           (axes[1], "concrete_iou_after", "(b) after RRDR")):
        keep = [i for i, r in enumerate(images) if r[key] is not None]
        hist = ax.twinx()
        hist.hist(ratio, bins=bins, weights=np.full(ratio.size, 1 / max(1, ratio.size)),
                  color="0.85")
        hist.set_ylabel("share of images")
        ax.set_zorder(hist.get_zorder() + 1)
        ax.patch.set_visible(False)
        ax.scatter(ratio[keep], [images[i][key] for i in keep], s=14, color="C3")
        ax.set_xlabel("concrete damage pixel ratio"), ax.set_title(title)
        ax.set_ylim(0, 1)
    axes[0].set_ylabel("image-wise IoU (concrete damage)")
    save_figure(fig, path)
