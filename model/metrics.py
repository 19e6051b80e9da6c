"""Evaluation measures (paper Sections 4.4-4.6): per-class precision, recall and IoU from a
confusion matrix, and depth MAE, RMSE and ARD. Plain numpy; label 0 is never counted.
"""

from typing import Any

import numpy as np

from glsynth.data.tokaido import DEPTH_FAR_M, DEPTH_NEAR_M

DEPTH_RANGE_M = (DEPTH_NEAR_M, DEPTH_FAR_M)
"""The Tokaido depth code's range; its ends are clips (too near, sky), not measured depths."""


def depth_valid(truth: Any) -> Any:
    """Pixels whose true depth is a measurement: strictly inside DEPTH_RANGE_M. The one rule
    for training (berHu) and evaluation; works on numpy arrays and torch tensors alike."""
    return (truth > DEPTH_RANGE_M[0]) & (truth < DEPTH_RANGE_M[1])


def confusion(truth: np.ndarray, predicted: np.ndarray, n_classes: int) -> np.ndarray:
    """(n_classes, n_classes) counts, rows = truth id 1..K, columns = predicted id 1..K;
    pixels with truth 0 are left out."""
    truth, predicted = np.asarray(truth).ravel(), np.asarray(predicted).ravel()
    if truth.shape != predicted.shape:
        raise ValueError(f"truth has {truth.size} pixels, prediction {predicted.size}")
    keep = truth > 0
    t, p = truth[keep].astype(np.int64) - 1, predicted[keep].astype(np.int64) - 1
    if t.size and (t.max() >= n_classes or p.min() < 0 or p.max() >= n_classes):
        raise ValueError(f"ids outside 1..{n_classes} in truth or prediction")
    return np.bincount(t * n_classes + p, minlength=n_classes ** 2).reshape(n_classes, n_classes)


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1), np.nan)


def segmentation_scores(matrix: np.ndarray, names: list[str]) -> dict:
    """Precision TP/(TP+FP), recall TP/(TP+FN), IoU TP/(TP+FP+FN) per class, in [0, 1].
    A class neither in the truth nor predicted has no scores (None) and is left out of the
    means; one in the truth but never predicted has precision 0; one only predicted has
    precision and IoU 0 and no recall."""
    m = np.asarray(matrix, np.float64)
    tp = np.diag(m)
    fp, fn = m.sum(0) - tp, m.sum(1) - tp
    precision, recall, iou = _ratio(tp, tp + fp), _ratio(tp, tp + fn), _ratio(tp, tp + fp + fn)
    present = (tp + fp + fn) > 0
    precision = np.where(present & np.isnan(precision), 0.0, precision)

    def clean(values: np.ndarray) -> list[float | None]:
        return [None if np.isnan(v) else float(v) for v in values]

    def mean(values: np.ndarray) -> float | None:
        v = values[~np.isnan(values)]
        return float(v.mean()) if v.size else None

    per_class = {name: {"precision": p, "recall": r, "iou": i, "pixels": int(n)}
                 for name, p, r, i, n in zip(names, clean(precision), clean(recall),
                                             clean(iou), m.sum(1))}
    return {"per_class": per_class,
            "mean": {"precision": mean(precision), "recall": mean(recall), "iou": mean(iou)}}


def depth_errors(predicted: np.ndarray, truth: np.ndarray) -> dict:
    """MAE and RMSE [m] and ARD (mean |e| / truth) over the pixels of depth_valid (the clipped
    ends of the Tokaido code, 0.5 m and 30 m, are not measured depths). Sums are returned so
    that images can be pooled."""
    p, t = np.asarray(predicted, np.float64).ravel(), np.asarray(truth, np.float64).ravel()
    if p.shape != t.shape:
        raise ValueError(f"depth prediction has {p.size} pixels, truth {t.size}")
    keep = depth_valid(t) & np.isfinite(p)
    e = p[keep] - t[keep]
    return {"pixels": int(keep.sum()), "abs": float(np.abs(e).sum()),
            "sq": float((e * e).sum()), "rel": float((np.abs(e) / t[keep]).sum())}


def pooled_depth(sums: list[dict]) -> dict:
    n = sum(s["pixels"] for s in sums)
    if n == 0:
        return {"pixels": 0, "mae_m": None, "rmse_m": None, "ard": None}
    return {"pixels": n, "mae_m": sum(s["abs"] for s in sums) / n,
            "rmse_m": float(np.sqrt(sum(s["sq"] for s in sums) / n)),
            "ard": sum(s["rel"] for s in sums) / n}
