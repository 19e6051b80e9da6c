"""Crack segmentation scores with a distance tolerance, as the crack-detection literature
reports them (CrackForest, DeepCrack): a predicted crack pixel counts as correct when a true
crack pixel lies within TOLERANCE_PX of it, and a true crack pixel as found when a predicted
one lies within TOLERANCE_PX; precision, recall and F1 from these counts summed over a test
set, at the single probability threshold that gives the best F1 over the whole set (the
"optimal dataset scale"). IoU is the plain pixel overlap at that threshold, also summed."""

from dataclasses import dataclass

import cv2
import numpy as np

TOLERANCE_PX = 2.0
THRESHOLDS = tuple(round(0.05 * i, 2) for i in range(1, 20))
"""Probability thresholds tried: 0.05 .. 0.95."""


@dataclass(frozen=True)
class Counts:
    """Pixel counts of one or more images at one threshold."""

    predicted: int = 0
    predicted_near_truth: int = 0
    truth: int = 0
    truth_near_prediction: int = 0
    intersection: int = 0
    union: int = 0

    def __add__(self, other: "Counts") -> "Counts":
        return Counts(*(a + b for a, b in zip(self.astuple(), other.astuple())))

    def astuple(self) -> tuple[int, ...]:
        return (self.predicted, self.predicted_near_truth, self.truth,
                self.truth_near_prediction, self.intersection, self.union)


def distance_to(mask: np.ndarray) -> np.ndarray:
    """Euclidean distance (px) from each pixel to the nearest True pixel of ``mask``; inf
    where the mask is empty."""
    if not mask.any():
        return np.full(mask.shape, np.inf, np.float32)
    return cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def count(predicted: np.ndarray, truth: np.ndarray, tolerance_px: float = TOLERANCE_PX,
          truth_distance: np.ndarray | None = None) -> Counts:
    """The counts of one boolean prediction against one boolean truth of the same shape."""
    if predicted.shape != truth.shape:
        raise ValueError(f"prediction {predicted.shape} and truth {truth.shape} differ in shape")
    near_truth = (truth_distance if truth_distance is not None else distance_to(truth)) \
        <= tolerance_px
    near_prediction = distance_to(predicted) <= tolerance_px
    return Counts(int(predicted.sum()), int((predicted & near_truth).sum()), int(truth.sum()),
                  int((truth & near_prediction).sum()), int((predicted & truth).sum()),
                  int((predicted | truth).sum()))


def scores(counts: Counts) -> dict[str, float]:
    """Precision, recall, F1 (tolerant) and IoU (exact) of summed counts; a ratio over no
    pixels is 0."""
    def ratio(a: int, b: int) -> float:
        return a / b if b else 0.0

    precision = ratio(counts.predicted_near_truth, counts.predicted)
    recall = ratio(counts.truth_near_prediction, counts.truth)
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": precision, "recall": recall, "f1": f1,
            "iou": ratio(counts.intersection, counts.union)}


def best_threshold(probabilities: list[np.ndarray], truths: list[np.ndarray],
                   thresholds: tuple[float, ...] = THRESHOLDS,
                   tolerance_px: float = TOLERANCE_PX) -> dict[str, float]:
    """Scores over a test set at the one threshold (of ``thresholds``) with the best F1
    summed over all its images; the threshold is in the result."""
    if len(probabilities) != len(truths) or not truths:
        raise ValueError("give one probability map per truth, and at least one")
    totals = {t: Counts() for t in thresholds}
    for prob, truth in zip(probabilities, truths):
        distance = distance_to(truth)
        for t in thresholds:
            totals[t] = totals[t] + count(prob >= t, truth, tolerance_px, distance)
    best = max(thresholds, key=lambda t: (scores(totals[t])["f1"], -abs(t - 0.5)))
    return {"threshold": best, **scores(totals[best])}
