"""Training FCN58 as in paper Section 4.3.

Adam with weight decay 1e-4, batch 8, random left-right flips (and, if asked, the photometric
augmentations of glsynth.model.augment), shuffling, the learning-rate
schedule 1e-3 / 1e-4 / 1e-5 for 200 / 50 / 10 epochs; median-frequency-balanced cross entropy
(label 0 ignored) or berHu for depth; validation on a held-out part of the training split after
each epoch. A run folder holds settings.json, class_weights.json, checkpoint.pt (every epoch,
written atomically; a run started again resumes from it), history.json, curves.png and, at the
end, model.pt. Checkpoints hold only tensors and plain data, so they load with
``weights_only=True``. Under torchrun each process trains on its own shard through
DistributedDataParallel; rank 0 writes the files.

Every random draw (validation split, initial weights, shuffles, flips, augmentations) is seeded
from glsynth.core.seeding by (seed, epoch, rank), so a resumed run sees the same batches as an
uninterrupted one. Depth is trained and evaluated on the same pixels (metrics.depth_valid).
"""

import bisect
import contextlib
import dataclasses
import functools
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from glsynth.model.augment import photometric
from glsynth.model.data import ImageFolder, TokaidoDataset
from glsynth.model.fcn58 import FCN58
from glsynth.model.losses import berhu, class_frequencies, mfb_weights, weighted_cross_entropy
from glsynth.model.metrics import (
    confusion,
    depth_errors,
    depth_valid,
    pooled_depth,
    segmentation_scores,
)
from glsynth.model.runtime import bf16_helps, load_torch, pick_device, predict_ids, save_torch
from glsynth.model.settings import (
    CLASS_NAMES,
    N_OUTPUTS,
    TrainSettings,
    settings_from_json,
    target_size,
)
from torch.utils.data import ConcatDataset, DataLoader, Dataset, DistributedSampler, Subset

from glsynth.core.children import die_with_parent
from glsynth.core.errors import UserError, named
from glsynth.core.fileio import atomic_write_json
from glsynth.core.runlock import DRIVER_LOCK, WORKERS_LOCK, RunLock
from glsynth.core.seeding import Stream, make_rng, make_seed
from glsynth.data.readers import read_class_weights, read_json
from glsynth.data.tokaido import FrameRecord

# Items of the training stream (glsynth.core.seeding.Stream.TRAINING).
_SPLIT, _WEIGHTS, _SHUFFLE, _FLIPS, _AUGMENT = range(5)


def torch_generator(seed: int) -> torch.Generator:
    """A CPU torch generator from a glsynth.core.seeding seed."""
    return torch.Generator().manual_seed(seed)


@contextlib.contextmanager
def seeded_torch(seed: int) -> Iterator[None]:
    """torch's global generator seeded for the block (layer initialisation draws from it),
    then put back as it was: nothing outside the block sees the seed."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)  # noqa: TID251 - the one place; seeds come from make_seed
        yield


def use_bf16(precision: str, device: torch.device) -> bool:
    return precision == "bf16" or (precision == "auto" and bf16_helps(device))


# --- data ------------------------------------------------------------------------------------
def training_sets(s: TrainSettings) -> tuple[Dataset, Dataset]:
    """(train, validation): the training split minus a seeded random validation part of its
    views; the plates (damage) and extra real folders stay in training."""
    split = TokaidoDataset(s.data, "train", s.task, views=s.views, image_size=s.image_size,
                           puretex=s.task == "damage" and s.puretex, cache=s.cache_inputs)
    frames = [i for i, r in enumerate(split.items) if isinstance(r, FrameRecord)]
    if not frames:
        raise UserError(f"--data {s.data!r} has no training images for task {s.task!r}")
    n_val = min(s.val_count, len(frames) // 5)
    order = make_rng(s.seed, 0, Stream.TRAINING, _SPLIT).permutation(len(frames))
    held_out = {frames[i] for i in order[:n_val]}
    val = Subset(split, sorted(held_out))
    parts: list[Dataset] = [Subset(split, [i for i in range(len(split)) if i not in held_out])]
    parts += [ImageFolder(e, s.task, s.image_size) for e in s.extra]
    return ConcatDataset(parts), val


def dataset_target(dataset: Dataset, index: int) -> torch.Tensor:
    """A sample's target without decoding its image, through Subset and ConcatDataset."""
    if isinstance(dataset, Subset):
        return dataset_target(dataset.dataset, dataset.indices[index])
    if isinstance(dataset, ConcatDataset):
        part = bisect.bisect_right(dataset.cumulative_sizes, index)
        start = dataset.cumulative_sizes[part - 1] if part else 0
        return dataset_target(dataset.datasets[part], index - start)
    return dataset.target(index)


def class_statistics(dataset: Dataset, n_classes: int) -> dict:
    """Pixel counts per class and pixels of the images containing it, over a dataset's
    targets, and the median-frequency-balancing weights from them."""
    pixels = np.zeros(n_classes, np.int64)
    image_pixels = np.zeros(n_classes, np.int64)
    for index in range(len(dataset)):
        ids = dataset_target(dataset, index).numpy().ravel()
        counts = np.bincount(ids, minlength=n_classes + 1)[1:n_classes + 1]
        pixels += counts
        image_pixels += np.where(counts > 0, int((ids > 0).sum()), 0)
    freq = class_frequencies(pixels, image_pixels)
    return {"pixels": pixels.tolist(), "image_pixels": image_pixels.tolist(),
            "weights": mfb_weights(freq).tolist()}


def flip_batch(images: torch.Tensor, targets: torch.Tensor,
               generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Left-right flip each sample with probability 1/2, image and target together."""
    flip = torch.rand(images.shape[0], generator=generator) < 0.5
    if flip.any():
        images, targets = images.clone(), targets.clone()
        images[flip] = images[flip].flip(-1)
        targets[flip] = targets[flip].flip(-1)
    return images, targets


# --- loss and evaluation ---------------------------------------------------------------------
def task_loss(task: str, output: torch.Tensor, target: torch.Tensor,
              weights: torch.Tensor | None) -> torch.Tensor:
    if task == "depth":
        return berhu(output[:, 0], target, depth_valid(target))
    return weighted_cross_entropy(output, target, weights)


@torch.no_grad()
def validate(model: torch.nn.Module, loader: DataLoader, task: str,
             weights: torch.Tensor | None, device: torch.device, autocast,
             channels_last: bool) -> dict:
    model.eval()
    losses, sums = [], []
    n = N_OUTPUTS[task]
    matrix = np.zeros((n, n), np.int64)
    for images, targets in loader:
        images, targets = prepare(images, device, channels_last), targets.to(device)
        with autocast():
            output = model(images)
        losses.append(float(task_loss(task, output, targets, weights)))
        if task == "depth":
            sums.append(depth_errors(output[:, 0].float().cpu().numpy(), targets.cpu().numpy()))
        else:
            matrix += confusion(targets.cpu().numpy(),
                                predict_ids(task, output, weights).cpu().numpy(), n)
    model.train()
    result = {"val_loss": float(np.mean(losses)) if losses else None}
    if task == "depth":
        result["val_mae_m"] = pooled_depth(sums)["mae_m"]
    else:
        result["val_miou"] = segmentation_scores(matrix, CLASS_NAMES[task])["mean"]["iou"]
    return result


def prepare(images: torch.Tensor, device: torch.device, channels_last: bool) -> torch.Tensor:
    images = images.to(device, non_blocking=True)
    return images.contiguous(memory_format=torch.channels_last) if channels_last else images


# --- the run ---------------------------------------------------------------------------------
def _distributed() -> tuple[int, int]:
    """(rank, world size); joins the process group under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        torch.distributed.init_process_group(backend)
        if torch.cuda.is_available():
            torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
    rank = torch.distributed.get_rank() if world > 1 else 0
    return rank, world


def _all_agree(flag: bool, world: int, device: torch.device) -> bool:
    """True on every rank once any rank says so (ranks must stop at the same step)."""
    if world == 1:
        return flag
    value = torch.tensor([float(flag)], device=device)
    torch.distributed.all_reduce(value, op=torch.distributed.ReduceOp.MAX)
    return bool(value.item())


def stored_settings(path: Path) -> TrainSettings:
    """A run folder's settings.json, checked as the command line checks its options."""
    fix = "it is damaged or not a glsynth run's: train into a new --out folder"
    data = read_json(path, {"task": str, "data": str, "image_size": list, "schedule": list},
                     fix)
    try:
        return settings_from_json(data)
    except UserError as err:
        raise UserError(f"{named(path)}: {err}; {fix}") from None
    except (TypeError, ValueError, KeyError) as err:
        raise UserError(f"{named(path)} does not hold valid training settings "
                        f"({type(err).__name__}); {fix}") from None


def open_run(run: Path, settings: TrainSettings) -> dict | None:
    """Create a run folder, or reopen one with the same settings; returns its checkpoint."""
    stored = run / "settings.json"
    if stored.exists():
        previous = stored_settings(stored)
        if previous != settings:
            raise UserError(f"--out {named(run)} holds a run with other settings; use a new "
                            "folder, or the same options to resume it")
        checkpoint = run / "checkpoint.pt"
        return load_torch(checkpoint) if checkpoint.exists() else None
    if any(p.name not in (DRIVER_LOCK, WORKERS_LOCK) for p in run.iterdir()):
        raise UserError(f"--out {named(run)} is not empty and holds no training run")
    atomic_write_json(stored, dataclasses.asdict(settings))
    return None


@dataclass
class _Run:
    """What one process of a training run holds between epochs."""

    settings: TrainSettings
    folder: Path
    rank: int
    world: int
    device: torch.device
    model: torch.nn.Module
    net: torch.nn.Module
    """The model, wrapped in DistributedDataParallel under torchrun."""
    optimizer: torch.optim.Optimizer
    weights: torch.Tensor | None
    bf16: bool
    history: list[dict]

    def autocast(self) -> torch.autocast:
        return torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.bf16)


def _class_weights(settings: TrainSettings, run: Path, train_set: Dataset, rank: int,
                   device: torch.device) -> torch.Tensor | None:
    """MFB weights, counted once per run folder (class_weights.json) from the targets."""
    if settings.task == "depth":
        return None
    stats_file = run / "class_weights.json"
    if stats_file.exists():
        stats = {"weights": read_class_weights(stats_file, N_OUTPUTS[settings.task])}
    else:
        stats = class_statistics(train_set, N_OUTPUTS[settings.task])
        if rank == 0:
            atomic_write_json(stats_file, {"classes": CLASS_NAMES[settings.task], **stats})
    return torch.tensor(stats["weights"], dtype=torch.float32, device=device)


def _start(settings: TrainSettings, run: Path, train_set: Dataset, rank: int, world: int,
           checkpoint: dict | None) -> tuple[_Run, int]:
    """The model, optimizer and history of a new or resumed run, and the first epoch to train."""
    device = pick_device(settings.device)
    if device.type == "cuda" and world > 1:
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    weights = _class_weights(settings, run, train_set, rank, device)
    with seeded_torch(make_seed(settings.seed, 0, Stream.TRAINING, _WEIGHTS)):
        model = FCN58(N_OUTPUTS[settings.task])
    if settings.channels_last:
        model = model.to(memory_format=torch.channels_last)
    model.to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=settings.learning_rate(0),
                                 weight_decay=settings.weight_decay)
    history: list[dict] = []
    start_epoch = 0
    if checkpoint is not None:
        model.load_state_dict(checkpoint["model"])
        optimizer.load_state_dict(checkpoint["optimizer"])
        history, start_epoch = list(checkpoint["history"]), int(checkpoint["epoch"])
        if checkpoint.get("stopped_by_budget"):
            start_epoch = settings.epochs  # the budget ended this run
    net = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model
    state = _Run(settings, run, rank, world, device, model, net, optimizer, weights,
                 use_bf16(settings.precision, device), history)
    return state, start_epoch


def _train_epoch(state: _Run, loader: DataLoader, epoch: int, deadline_s: float | None
                 ) -> tuple[list[float], int, bool]:
    """One pass over this rank's shard: (losses, images seen, whether the time budget ended
    it)."""
    s = state.settings
    for group in state.optimizer.param_groups:
        group["lr"] = s.learning_rate(epoch)
    flips = torch_generator(make_seed(s.seed, 0, Stream.TRAINING, _FLIPS, epoch, state.rank))
    augment = torch_generator(make_seed(s.seed, 0, Stream.TRAINING, _AUGMENT, epoch,
                                        state.rank))
    state.net.train()
    losses, images_seen = [], 0
    started = time.perf_counter()
    for images, targets in loader:
        images, targets = flip_batch(images, targets, flips)
        if s.augment:
            images = photometric(images.to(state.device), s.augment, augment)
        images = prepare(images, state.device, s.channels_last)
        targets = targets.to(state.device, non_blocking=True)
        with state.autocast():
            output = state.net(images)
        loss = task_loss(s.task, output, targets, state.weights)
        value = loss.detach().item()
        if not math.isfinite(value):
            raise FloatingPointError(f"training loss became {value} at epoch {epoch + 1}; lower "
                                     "the learning rate or use --precision fp32")
        state.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        state.optimizer.step()
        losses.append(value)
        images_seen += images.shape[0]
        out_of_time = deadline_s is not None and time.perf_counter() - started > deadline_s
        if _all_agree(out_of_time, state.world, state.device):
            return losses, images_seen, True
    return losses, images_seen, False


def _save_epoch(state: _Run, entry: dict, stopped: bool, log: Callable[[str], None]) -> None:
    """Checkpoint, history and curves after an epoch (rank 0 only)."""
    state.history.append(entry)
    if state.rank:
        return
    save_torch(state.folder / "checkpoint.pt",
               {"model": state.model.state_dict(), "optimizer": state.optimizer.state_dict(),
                "epoch": entry["epoch"], "history": state.history, "stopped_by_budget": stopped})
    atomic_write_json(state.folder / "history.json", state.history)
    plot_curves(state.history, state.folder / "curves.png", state.settings.task)
    log(json.dumps(entry))


def _save_model(state: _Run) -> None:
    s = state.settings
    save_torch(state.folder / "model.pt", {
        "task": s.task, "out_channels": N_OUTPUTS[s.task], "image_size": list(s.image_size),
        "target_size": list(target_size(s.image_size)),
        "mfb_weights": state.weights.cpu() if state.weights is not None else None,
        "state_dict": state.model.state_dict()})


def train(settings: TrainSettings, run: str | Path, log: Callable[[str], None] = print) -> dict:
    """Train (or resume) a run; returns the final history entry. Rank 0 holds the run
    folder's lock for the whole run. The device and the data are checked before the run
    folder is created, so a refused command leaves nothing behind."""
    run = Path(run)
    pick_device(settings.device)
    datasets = training_sets(settings)
    rank, world = _distributed()
    lock = RunLock(run).acquire() if rank == 0 else None
    try:
        checkpoint = open_run(run, settings) if rank == 0 else None
        if world > 1:
            torch.distributed.barrier()
            if rank:
                path = run / "checkpoint.pt"
                checkpoint = load_torch(path) if path.exists() else None
        return _train(settings, run, rank, world, checkpoint, datasets, log)
    finally:
        if lock is not None:
            lock.release()


def _train(settings: TrainSettings, run: Path, rank: int, world: int, checkpoint: dict | None,
           datasets: tuple[Dataset, Dataset], log: Callable[[str], None]) -> dict:
    train_set, val_set = datasets
    state, start_epoch = _start(settings, run, train_set, rank, world, checkpoint)
    loader_options = dict(batch_size=settings.batch_size, num_workers=settings.loader_workers,
                          pin_memory=state.device.type == "cuda",
                          persistent_workers=settings.loader_workers > 0,
                          worker_init_fn=functools.partial(die_with_parent, os.getpid()))
    sampler = DistributedSampler(train_set, num_replicas=world, rank=rank, shuffle=True,
                                 seed=make_seed(settings.seed, 0, Stream.TRAINING, _SHUFFLE),
                                 drop_last=world > 1)
    loader = DataLoader(train_set, sampler=sampler, **loader_options)
    val_loader = DataLoader(val_set, shuffle=False, **loader_options) if len(val_set) else None
    budget_s = settings.time_budget_min * 60 if settings.time_budget_min else None
    spent = float(state.history[-1]["train_seconds_total"]) if state.history else 0.0
    for epoch in range(start_epoch, settings.epochs):
        sampler.set_epoch(epoch)
        t0 = time.perf_counter()
        losses, seen, stopped = _train_epoch(
            state, loader, epoch, None if budget_s is None else budget_s - spent)
        seconds = time.perf_counter() - t0
        entry = {"epoch": epoch + 1, "lr": settings.learning_rate(epoch),
                 "precision": "bf16" if state.bf16 else "fp32",
                 "train_loss": float(np.mean(losses)) if losses else None,
                 "images": seen * world, "seconds": round(seconds, 3),
                 "images_per_s": round(seen * world / seconds, 3) if seconds else None}
        if val_loader is not None:
            entry.update(validate(state.model, val_loader, settings.task, state.weights,
                                  state.device, state.autocast, settings.channels_last))
        spent += time.perf_counter() - t0
        entry["train_seconds_total"] = round(spent, 3)
        _save_epoch(state, entry, stopped, log)
        if stopped:
            break
    if rank == 0:
        _save_model(state)
    if world > 1:
        torch.distributed.barrier()
    return state.history[-1] if state.history else {}


def plot_curves(history: list[dict], path: Path, task: str) -> None:
    import matplotlib.pyplot as plt

    from glsynth.core.plots import save_figure

    epochs = [h["epoch"] for h in history]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    a.plot(epochs, [h["train_loss"] for h in history], "o-", label="training")
    if any(h.get("val_loss") is not None for h in history):
        a.plot(epochs, [h.get("val_loss") for h in history], "s-", label="validation")
    a.set_xlabel("epoch"), a.set_ylabel("loss"), a.legend()
    key, label = ("val_mae_m", "validation MAE [m]") if task == "depth" else \
        ("val_miou", "validation mean IoU")
    b.plot(epochs, [h.get(key) for h in history], "s-", color="C1")
    b.set_xlabel("epoch"), b.set_ylabel(label)
    fig.suptitle(f"FCN58 {task}")
    save_figure(fig, path)
