"""The sim-to-real benchmark (glsynth bench sim2real): how well does a crack segmenter trained
on glsynth renders find cracks in real photographs, beside the same network trained on real
photographs?

A small U-Net (CrackUNet) is trained the same way on each glsynth dataset given (crack pixels
of the crack-width maps), on the whole of each other real folder given (photographs of
another kind: pavement beside concrete) and on the training share of the real folder; all
are scored on the rest of that folder (glsynth.measure.crack_scores: F1 with a 2 px
tolerance at the best single threshold, IoU). A real folder too small to split is tested
whole (test_share 1), and then no network is trained on it. Training samples square crops,
half of them centred on a crack pixel, flipped at random; everything draws from
Stream.TRAINING generators, so a run is repeated exactly on the same machine's CPU (on CUDA,
the same draws, but cuDNN's kernels do not repeat bit for bit)."""

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from glsynth.model.runtime import pick_device
from glsynth.model.train import seeded_torch
from torch import nn

from glsynth.core.errors import UserError
from glsynth.core.fileio import atomic_write_bytes, atomic_write_json, png_bytes
from glsynth.core.seeding import Stream, make_rng, make_seed
from glsynth.data.crack_folders import (
    CrackImage,
    group_members,
    read_groups,
    read_real_folder,
    read_synthetic,
)
from glsynth.measure.crack_scores import TOLERANCE_PX, best_threshold

CRACK_WEIGHT = 10.0
"""Weight of crack pixels in the loss: cracks are a few percent of the pixels or less."""
EXAMPLES = 4
"""Test images shown in predictions.png."""
CPU = torch.device("cpu")
"""Where train_network and predict run unless told otherwise."""


@dataclass(frozen=True)
class Sim2RealSettings:
    steps: int = 300
    """Optimiser steps per network."""
    crop: int = 128
    """Side of the square training crops, pixels (a multiple of 8)."""
    batch: int = 8
    width: int = 16
    """Channels of the U-Net's first level (doubled at each of its three levels down)."""
    learning_rate: float = 2e-3
    test_share: float = 0.3
    """Share of the real folder held out for testing (the rest trains the real network); 1
    tests on all of it and trains no network on it."""
    seed: int = 0
    repeats: int = 3
    """Networks trained per training set, each from its own generators (repeat_item); the one
    of median F1 (the lower middle one for an even count) gives the scores and the picture,
    and every repeat's scores are kept. Three by default: one network's F1 spreads by up to
    0.13 over its draws. Why: docs/design.md, "The sim-to-real benchmark"."""
    device: str = "auto"
    """Where the networks train and predict: auto (CUDA when there is one), cpu, cuda or
    cuda:N. The draws are the same on each; the arithmetic is not, so compare networks
    trained on one device."""

    def __post_init__(self) -> None:
        checks = (("steps", 1 <= self.steps <= 10**6, "an integer in [1, 1000000]"),
                  ("crop", 16 <= self.crop <= 1024 and self.crop % 8 == 0,
                   "a multiple of 8 in [16, 1024]"),
                  ("batch", 1 <= self.batch <= 256, "an integer in [1, 256]"),
                  ("width", 4 <= self.width <= 128, "an integer in [4, 128]"),
                  ("learning_rate", 0 < self.learning_rate <= 1, "in (0, 1]"),
                  ("test_share", 0 < self.test_share <= 1,
                   "in (0, 1]; 1 tests on the whole real folder"),
                  ("seed", self.seed >= 0, "an integer >= 0"),
                  ("repeats", 1 <= self.repeats <= 100, "an integer in [1, 100]"))
        for name, ok, expected in checks:
            if not ok:
                value = getattr(self, name)
                raise UserError(f"--{name.replace('_', '-')} {value}: must be {expected}")


def _block(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, padding=1), nn.BatchNorm2d(c_out),
                         nn.ReLU(inplace=True), nn.Conv2d(c_out, c_out, 3, padding=1),
                         nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


class CrackUNet(nn.Module):
    """A U-Net of three levels down and up (sides must be multiples of 8); one logit a
    pixel."""

    def __init__(self, width: int = 16) -> None:
        super().__init__()
        w = [width, 2 * width, 4 * width, 8 * width]
        self.down = nn.ModuleList([_block(3, w[0]), _block(w[0], w[1]), _block(w[1], w[2])])
        self.bottom = _block(w[2], w[3])
        self.up = nn.ModuleList([nn.ConvTranspose2d(w[i + 1], w[i], 2, stride=2)
                                 for i in (2, 1, 0)])
        self.merge = nn.ModuleList([_block(2 * w[i], w[i]) for i in (2, 1, 0)])
        self.head = nn.Conv2d(w[0], 1, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
            x = F.max_pool2d(x, 2)
        x = self.bottom(x)
        for up, merge, skip in zip(self.up, self.merge, reversed(skips)):
            x = merge(torch.cat([up(x), skip], dim=1))
        return self.head(x)[:, 0]


def _normalised(rgb: np.ndarray) -> np.ndarray:
    """(3, H, W) float32, each image to zero mean and unit spread per channel: the networks
    see contrast, not a camera's overall brightness and tint."""
    x = rgb.astype(np.float32).transpose(2, 0, 1) / 255.0
    mean = x.mean(axis=(1, 2), keepdims=True)
    std = x.std(axis=(1, 2), keepdims=True)
    return (x - mean) / np.maximum(std, 1e-3)


def _crop_at(image: CrackImage, crop: int, rng: np.random.Generator
             ) -> tuple[np.ndarray, np.ndarray]:
    """A random crop (padded by reflection where the image is smaller), centred on a crack
    pixel half of the time, flipped at random."""
    rgb, crack = image.rgb, image.crack
    pad_y, pad_x = max(0, crop - rgb.shape[0]), max(0, crop - rgb.shape[1])
    if pad_y or pad_x:
        rgb = np.pad(rgb, ((0, pad_y), (0, pad_x), (0, 0)), mode="reflect")
        crack = np.pad(crack, ((0, pad_y), (0, pad_x)))
    h, w = crack.shape
    ys, xs = np.nonzero(crack)
    if ys.size and rng.random() < 0.5:
        k = int(rng.integers(ys.size))
        top = int(np.clip(ys[k] - crop // 2, 0, h - crop))
        left = int(np.clip(xs[k] - crop // 2, 0, w - crop))
    else:
        top, left = int(rng.integers(h - crop + 1)), int(rng.integers(w - crop + 1))
    x = rgb[top:top + crop, left:left + crop]
    y = crack[top:top + crop, left:left + crop]
    if rng.random() < 0.5:
        x, y = x[:, ::-1], y[:, ::-1]
    if rng.random() < 0.5:
        x, y = x[::-1], y[::-1]
    return _normalised(np.ascontiguousarray(x)), np.ascontiguousarray(y)


SPLIT_ITEM = 2
"""The Stream.TRAINING item that shuffles the real folder before its split."""


def repeat_item(repeat: int) -> int:
    """The Stream.TRAINING item of a repeat's network: 0 for the first (every run before
    repeats, the same network), then past SPLIT_ITEM, so that no network draws the split's
    numbers."""
    return 0 if repeat == 0 else SPLIT_ITEM + repeat


def train_network(images: list[CrackImage], settings: Sim2RealSettings, item: int,
                  device: torch.device = CPU) -> tuple[CrackUNet, dict]:
    """A CrackUNet trained on ``images`` on ``device``, its initial weights and draws from
    ``item``'s generators (the weights drawn on the CPU, so the same on every device)."""
    rng = make_rng(settings.seed, 0, Stream.TRAINING, item)
    with seeded_torch(make_seed(settings.seed, 0, Stream.TRAINING, item)):
        net = CrackUNet(settings.width)
    net.to(device)
    optimiser = torch.optim.Adam(net.parameters(), lr=settings.learning_rate)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, settings.learning_rate,
                                                   total_steps=settings.steps)
    weight = torch.tensor(CRACK_WEIGHT, device=device)
    net.train()
    t0, losses = time.perf_counter(), []
    for _ in range(settings.steps):
        picks = rng.integers(len(images), size=settings.batch)
        crops = [_crop_at(images[int(i)], settings.crop, rng) for i in picks]
        x = torch.from_numpy(np.stack([c[0] for c in crops])).to(device)
        y = torch.from_numpy(np.stack([c[1] for c in crops]).astype(np.float32)).to(device)
        loss = F.binary_cross_entropy_with_logits(net(x), y, pos_weight=weight)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        losses.append(float(loss.detach()))
    return net, {"train_s": time.perf_counter() - t0, "images": len(images),
                 "first_loss": losses[0], "last_loss": float(np.mean(losses[-20:]))}


@torch.no_grad()
def predict(net: CrackUNet, rgb: np.ndarray, device: torch.device = CPU
            ) -> np.ndarray:
    """(H, W) float32 crack probability of a whole image (padded to multiples of 8), by
    ``net`` on ``device``."""
    net.eval()
    h, w = rgb.shape[:2]
    x = _normalised(rgb)
    x = np.pad(x, ((0, 0), (0, -h % 8), (0, -w % 8)), mode="reflect")
    logits = net(torch.from_numpy(x)[None].to(device))[0, :h, :w]
    return torch.sigmoid(logits).cpu().numpy()


def split_real(images: list[CrackImage], settings: Sim2RealSettings
               ) -> tuple[list[CrackImage], list[CrackImage]]:
    """(train, test) of a real folder: a seeded shuffle, ``test_share`` of it (at least one
    image each) for testing; with ``test_share`` 1, no training share and all of it to
    test."""
    if settings.test_share == 1:
        return [], list(images)
    if len(images) < 2:
        raise UserError(f"the real folder holds {len(images)} image; give at least 2, one to "
                        "train on and one to test on, or test on all of it with --test-share 1")
    order = make_rng(settings.seed, 0, Stream.TRAINING, SPLIT_ITEM).permutation(len(images))
    n_test = min(len(images) - 1, max(1, round(settings.test_share * len(images))))
    test = {int(i) for i in order[:n_test]}
    return ([im for i, im in enumerate(images) if i not in test],
            [im for i, im in enumerate(images) if i in test])


def _picture(test: list[CrackImage], predictions: dict[str, list[np.ndarray]],
             thresholds: dict[str, float]) -> np.ndarray:
    """Rows of test images: the photograph, its true cracks, then each network's cracks at
    its threshold (white; a true crack it missed in red)."""
    rows = []
    for k in range(min(EXAMPLES, len(test))):
        image = test[k]
        tiles = [image.rgb, np.repeat(image.crack[..., None] * np.uint8(255), 3, axis=2)]
        for name, probs in predictions.items():
            found = probs[k] >= thresholds[name]
            tile = np.repeat(found[..., None] * np.uint8(255), 3, axis=2)
            tile[image.crack & ~found] = (255, 0, 0)
            tiles.append(tile)
        rows.append(np.concatenate(tiles, axis=1))
    width = max(r.shape[1] for r in rows)
    return np.concatenate([np.pad(r, ((0, 4), (0, width - r.shape[1]), (0, 0)))
                           for r in rows], axis=0)


REAL = "real"
"""The name of the network trained on the training share of the real folder."""
KINDS = {"synthetic": "glsynth dataset", "other_real": "other real folder, whole",
         "real": "training share of the real folder"}
"""What each kind of network is trained on, as the summary says it."""


def network_names(synthetic: Sequence[str | Path], other_real: Sequence[str | Path],
                  real: str | Path) -> list[str]:
    """The networks' names, each dataset's and other real folder's folder name, refused
    where two are alike, one is 'real' or an other real folder is the real folder itself."""
    for path in other_real:
        if Path(path).resolve() == Path(real).resolve():
            raise UserError(f"--other-real {path}: is the --real folder itself, whose images "
                            "test every network; give a folder of other photographs")
    names = [Path(s).resolve().name for s in [*synthetic, *other_real]]
    if len(set(names)) != len(names) or REAL in names:
        given = " ".join(map(str, [*synthetic, *other_real]))
        raise UserError(f"--synthetic/--other-real {given}: give folders of different folder "
                        f"names, none named '{REAL}' (they name the networks)")
    return names


def _training_sets(synthetic: Sequence[str | Path], other_real: Sequence[str | Path],
                   real_train: list[CrackImage]) -> list[tuple[str, list[CrackImage]]]:
    """(kind, images) of every network, in the order of the names: each real folder is
    read before any synthetic dataset, so a bad folder is refused before the slow reads."""
    others = [("other_real", read_real_folder(path)) for path in other_real]
    sets = [("synthetic", read_synthetic(path)) for path in synthetic]
    return [*sets, *others, *([(REAL, real_train)] if real_train else [])]


class ScoredRun(NamedTuple):
    score: dict
    """best_threshold's scores on the test images."""
    training: dict
    """train_network's figures."""
    examples: list[np.ndarray]
    """Its predictions of the test images predictions.png shows."""


def held_out_groups(groups: dict[str, list[int]], images: list[CrackImage],
                    test: list[CrackImage]) -> dict[str, list[int]]:
    """Each group (indices into the real folder's ``images``) as indices into ``test``, the
    held-out share; a group with no held-out image, or none that marks a crack (its F1 is 0
    whatever a network finds), is refused."""
    at = {image.name: k for k, image in enumerate(test)}
    out = {}
    for group, members in groups.items():
        out[group] = [at[images[i].name] for i in members if images[i].name in at]
        if not out[group]:
            raise UserError(f"--groups: group {group!r} has no image among the "
                            f"{len(test)} held out for testing; give --test-share 1 to test on "
                            "the whole real folder, or a group with more images")
        if not any(test[k].crack.any() for k in out[group]):
            raise UserError(f"--groups: group {group!r} has no crack pixel in its held-out "
                            "masks, so its F1 is 0 whatever a network finds; add cracked "
                            "images to it")
    return out


def scored_run(images: list[CrackImage], test: list[CrackImage], settings: Sim2RealSettings,
               item: int, device: torch.device, groups: dict[str, list[int]] | None = None
               ) -> ScoredRun:
    """A network trained on ``images`` from ``item``'s draws (every training set draws the
    same crops' randomness and initial weights for one item), scored on ``test``, and on each
    group of ``test`` (indices) at its own best threshold, as if the group were the test
    folder."""
    net, training = train_network(images, settings, item, device)
    probs = [predict(net, image.rgb, device) for image in test]
    score = best_threshold(probs, [image.crack for image in test])
    if groups:
        score["groups"] = {group: best_threshold([probs[k] for k in members],
                                                 [test[k].crack for k in members])
                           for group, members in groups.items()}
    return ScoredRun(score, training, probs[:EXAMPLES])


def _network_entry(kind: str, runs: list[ScoredRun], median: int) -> dict:
    """A network's entry in sim2real.json: its kind and the median run's scores and training
    figures; with repeats, also which run that is, the F1s' range and every run's figures."""
    entry = {"trained_on": kind, **runs[median].score, **runs[median].training}
    if len(runs) > 1:
        f1s = [run.score["f1"] for run in runs]
        entry.update(median_repeat=median, f1_range=[min(f1s), max(f1s)],
                     repeats=[{**run.score, **run.training} for run in runs])
    return entry


def run_sim2real(synthetic: Sequence[str | Path], real: str | Path, out: str | Path,
                 settings: Sim2RealSettings, other_real: Sequence[str | Path] = (),
                 groups: str | Path | None = None) -> dict:
    """Train one network on each dataset of ``synthetic``, one on each whole folder of
    ``other_real`` and one on the training share of ``real`` (none with test_share 1), the
    same way; score them all on the rest of ``real``, and on each group of the ``groups``
    file (read_groups) among it. Writes sim2real.json (again after each network; "complete"
    once all are in) and predictions.png into ``out`` and returns the result (networks by
    name: each dataset's and other folder's name, then "real")."""
    out = Path(out)
    device = pick_device(settings.device)
    names = network_names(synthetic, other_real, real)
    named_groups = read_groups(groups) if groups is not None else {}
    real_images = read_real_folder(real)
    real_train, test = split_real(real_images, settings)
    tested = held_out_groups(group_members(named_groups, real_images), real_images, test)
    sets = _training_sets(synthetic, other_real, real_train)
    names = [*names, REAL][:len(sets)]
    out.mkdir(parents=True, exist_ok=True)
    result: dict = {"settings": dataclasses.asdict(settings),
                    "synthetic": [str(s) for s in synthetic], "real": str(real),
                    "other_real": [str(o) for o in other_real],
                    "device": str(device), "tolerance_px": TOLERANCE_PX,
                    "test_images": len(test),
                    "groups": {group: len(members) for group, members in tested.items()},
                    "real_train_images": len(real_train), "real_trained": bool(real_train),
                    "networks": {}, "complete": False}
    predictions, thresholds = {}, {}
    for name, (kind, images) in zip(names, sets):
        runs = [scored_run(images, test, settings, repeat_item(r), device, tested)
                for r in range(settings.repeats)]
        median = sorted(range(len(runs)), key=lambda r: runs[r].score["f1"])[(len(runs) - 1) // 2]
        predictions[name] = runs[median].examples
        thresholds[name] = runs[median].score["threshold"]
        result["networks"][name] = _network_entry(kind, runs, median)
        # Each network takes minutes on a CPU: a run stopped early keeps those finished (a
        # network with repeats once all its repeats are in).
        result["complete"] = len(result["networks"]) == len(sets)
        atomic_write_json(out / "sim2real.json", result)
    atomic_write_bytes(out / "predictions.png", png_bytes(_picture(test, predictions,
                                                                   thresholds)))
    return result


def summary(result: dict) -> str:
    lines = [f"{len(result['networks'])} networks, scored on {result['test_images']} held-out "
             f"real images (F1 with a {result['tolerance_px']:g} px tolerance):"]
    for name, s in result["networks"].items():
        lines.append(f"  trained on {name:12s} ({KINDS[s['trained_on']]}, {s['images']} "
                     f"images, {s['train_s']:.0f} s): F1 {s['f1']:.3f} (P {s['precision']:.3f},"
                     f" R {s['recall']:.3f}) IoU {s['iou']:.3f} at threshold "
                     f"{s['threshold']:.2f}"
                     + (f"; the median of {len(s['repeats'])} repeats, F1 "
                        f"{s['f1_range'][0]:.3f}-{s['f1_range'][1]:.3f}" if "repeats" in s
                        else ""))
        if "groups" in s:
            lines.append("    by group: " + ", ".join(
                f"{group} F1 {g['f1']:.3f} (P {g['precision']:.3f}, R {g['recall']:.3f})"
                for group, g in s["groups"].items()))
    if not result["real_trained"]:
        lines.append(f"  no network trained on the real folder: --test-share 1 tests on all "
                     f"{result['test_images']} of its images")
    return "\n".join(lines)
