"""Training losses (paper Section 4.3): median-frequency-balanced cross entropy with label 0
ignored, and the reverse Huber (berHu) loss for depth.

Class ids in label maps are 1..K; channel k of the network scores id k + 1.
"""

import numpy as np
import torch
import torch.nn.functional as F


def class_frequencies(pixel_counts: np.ndarray, image_counts: np.ndarray) -> np.ndarray:
    """Eigen & Fergus frequency per class: pixels of the class over the pixels of the images
    that contain it. pixel_counts[k]: pixels of class k; image_counts[k]: total pixels of the
    images where class k appears. Absent classes (no image) get NaN."""
    pixels = np.asarray(pixel_counts, np.float64)
    images = np.asarray(image_counts, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(images > 0, pixels / np.where(images > 0, images, 1), np.nan)


def mfb_weights(frequencies: np.ndarray) -> np.ndarray:
    """median(freq) / freq_k, the median over classes present; absent classes get weight 0
    (one NaN or inf would otherwise poison the median and every weight)."""
    f = np.asarray(frequencies, np.float64)
    present = np.isfinite(f) & (f > 0)
    weights = np.zeros_like(f)
    if present.any():
        weights[present] = np.median(f[present]) / f[present]
    return weights


def weighted_cross_entropy(logits: torch.Tensor, labels: torch.Tensor,
                           weights: torch.Tensor) -> torch.Tensor:
    """Mean of w[label] * CE over labelled pixels (id 0 ignored), normalised by the summed
    weights. All-ignored or zero-weight batches give 0 with finite gradients, where PyTorch's
    own weighted mean gives 0/0."""
    if logits.shape[-2:] != labels.shape[-2:]:
        raise ValueError(f"logits {tuple(logits.shape)} and labels {tuple(labels.shape)} "
                         "differ in size: targets must be ceil(H/3) x ceil(W/3) of the input")
    target = labels.long() - 1  # -1 = ignore
    per_pixel = F.cross_entropy(logits.float(), target.clamp_min(0), reduction="none")
    w = torch.where(target >= 0, weights.to(logits.device)[target.clamp_min(0)],
                    torch.zeros((), device=logits.device))
    return (w * per_pixel).sum() / w.sum().clamp_min(1e-12)


def berhu(prediction: torch.Tensor, target: torch.Tensor,
          valid: torch.Tensor | None = None) -> torch.Tensor:
    """Reverse Huber: |e| where |e| <= c, (e^2 + c^2) / (2c) above, c = 0.2 max|e|.

    c is detached and clamped to >= 1e-6: with every error 0 a plain ``where`` would divide
    0/0 in the unused branch and give NaN gradients everywhere."""
    prediction = prediction.float().reshape(target.shape)
    error = (prediction - target.float()).abs()
    if valid is not None:
        error = error[valid]
    if error.numel() == 0:
        return prediction.sum() * 0.0
    c = (0.2 * error.max()).detach().clamp_min(1e-6)
    loss = torch.where(error <= c, error, (error * error + c * c) / (2 * c))
    return loss.mean()
