"""Trained FCN58 runs in use: prediction on photos and evaluation on a Tokaido-layout split
(paper Sections 4.4-4.6). Works on glsynth's data and on the released Tokaido dataset.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from glsynth.model.data import TokaidoDataset, image_tensor
from glsynth.model.fcn58 import FCN58
from glsynth.model.metrics import confusion, depth_errors, pooled_depth, segmentation_scores
from glsynth.model.runtime import bf16_helps, load_torch, pick_device, predict_ids
from glsynth.model.settings import CLASS_NAMES, N_OUTPUTS
from PIL import Image

from glsynth.core.errors import UserError, named
from glsynth.core.fileio import (
    atomic_write_bytes,
    atomic_write_json,
    distinct_stems,
    npy_bytes,
    png_bytes,
)
from glsynth.core.images import nearest_resize, read_photo
from glsynth.core.palette import COMPONENT_RGB, DAMAGE_RGB, depth_rgb, overlay
from glsynth.data.readers import read_json
from glsynth.data.tokaido import encode_depth


@dataclass
class Predictor:
    task: str
    model: FCN58
    image_size: tuple[int, int]
    weights: torch.Tensor | None
    device: torch.device

    @torch.no_grad()
    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) in [0, 1] at image_size -> (N, h, w) ids 1..K (int64) or metres
        (float32) at a third of the size, rounded up."""
        images = images.to(self.device).contiguous(memory_format=torch.channels_last)
        with torch.autocast(self.device.type, dtype=torch.bfloat16,
                            enabled=bf16_helps(self.device)):
            output = self.model(images)
        if self.task == "depth":
            return output[:, 0].float().cpu()
        return predict_ids(self.task, output, self.weights).cpu()

    def photo(self, path: str | Path) -> tuple[np.ndarray, np.ndarray]:
        """(RGB uint8 at the photo's own size, prediction at a third of image_size)."""
        rgb = read_photo(path)
        return rgb, self(image_tensor(rgb, self.image_size)[None])[0].numpy()


MODEL_KEYS = ("task", "out_channels", "image_size", "mfb_weights", "state_dict")


def load_predictor(run: str | Path, device: str = "auto") -> Predictor:
    """The trained network of a run folder, checked against the run's settings.json."""
    path = Path(run) / "model.pt"
    if not path.is_file():
        raise UserError(f"run {named(run)} has no model.pt: train it first "
                        "(glsynth train ... --out RUN) or check the path")
    data = load_torch(path)
    missing = [k for k in MODEL_KEYS if k not in data]
    if missing or data["task"] not in N_OUTPUTS or \
            data["out_channels"] != N_OUTPUTS[data["task"]]:
        raise UserError(f"{named(path)} is not a glsynth model (missing {missing or 'nothing'}, "
                        f"task {data.get('task')!r}); train again into a new --out folder")
    settings = Path(run) / "settings.json"
    if settings.is_file():
        task = read_json(settings, {"task": str}, "the run folder is damaged: train again "
                         "into a new --out folder")["task"]
        if task != data["task"]:
            raise UserError(f"run {named(run)}: model.pt is a {data['task']} network but "
                            f"settings.json says {task}; the folder mixes two runs: train "
                            "again into a new --out folder")
    model = FCN58(int(data["out_channels"]))
    try:
        model.load_state_dict(data["state_dict"])
    except (RuntimeError, TypeError, AttributeError) as err:
        raise UserError(f"{named(path)}: its weights do not fit FCN58 "
                        f"({str(err).splitlines()[0]}); train again into a new --out "
                        "folder") from err
    dev = pick_device(device)
    model = model.to(memory_format=torch.channels_last).to(dev).eval()
    weights = data["mfb_weights"]
    return Predictor(data["task"], model, tuple(data["image_size"]),
                     weights.to(dev) if weights is not None else None, dev)


def resize_map(values: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A prediction map brought to (width, height): nearest for ids, bilinear for depth."""
    if values.shape[::-1] == tuple(size):
        return values
    if values.dtype.kind != "f":
        return nearest_resize(values, (size[1], size[0]))
    return np.asarray(Image.fromarray(values.astype(np.float32)).resize(
        size, Image.Resampling.BILINEAR))


def picture(task: str, rgb: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A prediction over its photo: ids as a palette overlay, depth colour-mapped."""
    values = resize_map(values, (rgb.shape[1], rgb.shape[0]))
    if task == "depth":
        return depth_rgb(values)
    palette = COMPONENT_RGB if task == "component" else DAMAGE_RGB
    return overlay(rgb, values, palette, skip=(0, 1) if task == "damage" else (0,))


def predict_files(run: str | Path, images: list[str], out: str | Path,
                  device: str = "auto") -> list[Path]:
    """Per photo, at a third of the run's image size: <stem>_<task>.png (uint8 ids, or uint16
    depth in the Tokaido code) and, for depth, <stem>_depth.npy (float32 metres); plus
    <stem>_<task>_overlay.png at the photo's size. Stems are distinct_stems of the paths, so
    photos that share a file name keep their own outputs."""
    predictor = load_predictor(run, device)
    out = Path(out)
    written = []
    for name, path in zip(distinct_stems(images), images):
        rgb, values = predictor.photo(path)
        stem = f"{name}_{predictor.task}"
        if predictor.task == "depth":
            atomic_write_bytes(out / f"{stem}.npy", npy_bytes(values.astype(np.float32)))
            atomic_write_bytes(out / f"{stem}.png", png_bytes(encode_depth(values)))
        else:
            atomic_write_bytes(out / f"{stem}.png", png_bytes(values.astype(np.uint8)))
        atomic_write_bytes(out / f"{stem}_overlay.png",
                           png_bytes(picture(predictor.task, rgb, values)))
        written.append(out / f"{stem}_overlay.png")
    return written


def evaluate(run: str | Path, data: str | Path, split: str = "test",
             out: str | Path | None = None, examples: int = 6, puretex: bool = True,
             device: str = "auto") -> dict:
    """Metrics of a run on a split: per-class precision/recall/IoU and means (components,
    damage), or MAE/RMSE/ARD within [0.5, 30) m (depth); per-image damage IoU and damage pixel
    ratio for the Fig. 18 plot. Writes metrics.json, confusion.png and example overlays."""
    predictor = load_predictor(run, device)
    task = predictor.task
    dataset = TokaidoDataset(data, split, task, image_size=predictor.image_size,
                             puretex=puretex and task == "damage")
    if len(dataset) == 0:
        raise UserError(f"--data {named(data)} has no {split} images for task {task!r}")
    out = Path(out) if out is not None else Path(run) / f"eval_{split}"
    n = predictor.model.out_channels
    matrix = np.zeros((n, n), np.int64)
    sums, per_image = [], []
    for index in range(len(dataset)):
        image, target = dataset[index]
        predicted = predictor(image[None])[0].numpy()
        truth = target.numpy()
        if task == "depth":
            sums.append(depth_errors(predicted, truth))
        else:
            m = confusion(truth, predicted, n)
            matrix += m
            per_image.append({"image": dataset.items[index].image,
                              **image_scores(task, m, truth)})
        if index < examples:
            rgb = (image.permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
            row = [rgb, picture(task, rgb, truth), picture(task, rgb, predicted)]
            atomic_write_bytes(out / "examples" / f"example_{index}.png",
                               png_bytes(np.concatenate(row, axis=1)))
    metrics = {"task": task, "split": split, "images": len(dataset), "data": str(data)}
    if task == "depth":
        metrics["depth"] = pooled_depth(sums)
    else:
        metrics.update(segmentation_scores(matrix, CLASS_NAMES[task]))
        metrics["confusion"] = matrix.tolist()
        metrics["per_image"] = per_image
        plot_confusion(matrix, CLASS_NAMES[task], out / "confusion.png")
    atomic_write_json(out / "metrics.json", metrics)
    return metrics


def image_scores(task: str, matrix: np.ndarray, truth: np.ndarray) -> dict:
    """Per image: damage IoU (classes 2-3 together) and damage pixel ratio, or mean IoU."""
    if task == "damage":
        tp = matrix[1:, 1:].sum()
        fp, fn = matrix[0, 1:].sum(), matrix[1:, 0].sum()
        labelled = int((truth > 0).sum())
        return {"damage_iou": float(tp / (tp + fp + fn)) if tp + fp + fn else None,
                "damage_pixel_ratio": float((truth >= 2).sum() / labelled) if labelled else 0.0}
    return {"miou": segmentation_scores(matrix, CLASS_NAMES[task])["mean"]["iou"]}


def plot_confusion(matrix: np.ndarray, names: list[str], path: Path) -> None:
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    rows = matrix.sum(1, keepdims=True)
    share = np.divide(matrix, rows, out=np.zeros(matrix.shape), where=rows > 0)
    fig, ax = plt.subplots(figsize=(1.0 + 0.8 * len(names), 0.8 + 0.7 * len(names)))
    ax.imshow(share, vmin=0, vmax=1, cmap="Blues")
    for (i, j), v in np.ndenumerate(share):
        ax.text(j, i, f"{100 * v:.0f}", ha="center", va="center",
                color="white" if v > 0.5 else "black", fontsize=8)
    ax.set_xticks(range(len(names)), names, rotation=45, ha="right")
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel("predicted"), ax.set_ylabel("truth")
    ax.set_title("confusion [% of truth row]")
    save_figure(fig, path)
