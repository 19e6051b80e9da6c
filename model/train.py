"""Training FCN58 as in paper Section 4.3.

Adam with weight decay 1e-4, batch 8, random left-right flips, shuffling, the learning-rate
schedule 1e-3 / 1e-4 / 1e-5 for 200 / 50 / 10 epochs; median-frequency-balanced cross entropy
(label 0 ignored) or berHu for depth; validation on a held-out part of the training split after
each epoch. A run folder holds settings.json, class_weights.json, checkpoint.pt (every epoch,
written atomically; a run started again resumes from it), history.json, curves.png and, at the
end, model.pt. Checkpoints hold only tensors and plain data, so they load with
``weights_only=True``. Under torchrun each process trains on its own shard through
DistributedDataParallel; rank 0 writes the files.

Shuffling and flips come from generators seeded by (seed, epoch), so a resumed run sees the same
batches as an uninterrupted one.
"""

import bisect
import dataclasses
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import ConcatDataset, DataLoader, Dataset, Subset

from glsynth.core.fileio import atomic_write_bytes, atomic_write_json
from glsynth.data.tokaido import FrameRecord
from glsynth.model.data import N_OUTPUTS, TASKS, ImageFolder, TokaidoDataset, target_size
from glsynth.model.fcn58 import FCN58
from glsynth.model.losses import berhu, class_frequencies, mfb_weights, weighted_cross_entropy
from glsynth.model.metrics import confusion, depth_errors, pooled_depth, segmentation_scores

PAPER_SCHEDULE = ((1e-3, 200), (1e-4, 50), (1e-5, 10))
CLASS_NAMES = {"component": ["nonbridge", "slab", "beam", "column", "nonstructural", "rail",
                             "sleeper", "other"],
               "damage": ["no_damage", "concrete", "rebar"]}


@dataclass(frozen=True)
class TrainSettings:
    task: str
    data: str
    """Tokaido-layout dataset root (glsynth's output or the released dataset)."""
    extra: tuple[str, ...] = ()
    """Folders of real labelled photos mixed into training (images/ + labels/)."""
    image_size: tuple[int, int] = (1920, 1080)
    """(width, height) images are resized to; targets are a third, rounded up."""
    batch_size: int = 8
    schedule: tuple[tuple[float, int], ...] = PAPER_SCHEDULE
    """(learning rate, epochs) stages."""
    weight_decay: float = 1e-4
    val_count: int = 300
    """Training images held out for validation (at most a fifth of them)."""
    puretex: bool = True
    """Damage task: add the pure-texture plates to training."""
    seed: int = 0
    precision: str = "auto"
    """'bf16' (autocast), 'fp32', or 'auto': bf16 where the hardware has it (see bf16_helps)."""
    channels_last: bool = True
    loader_workers: int = 1
    time_budget_s: float | None = None
    """Stop after the step that passes this many seconds of training (then validate, save)."""
    views: str | None = None
    """'regular', 'closeup' or 'all'; default per task (paper Section 4.2)."""
    device: str = field(default="auto", compare=False)

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"--task {self.task!r}: choose one of {', '.join(TASKS)}")
        if self.batch_size < 1:
            raise ValueError(f"--batch-size {self.batch_size}: give at least 1")
        if not self.schedule or any(lr <= 0 or n < 1 for lr, n in self.schedule):
            raise ValueError(f"--schedule {self.schedule}: give LR:EPOCHS stages with LR > 0 "
                             "and EPOCHS >= 1, e.g. 1e-3:200,1e-4:50,1e-5:10")
        if self.precision not in ("auto", "bf16", "fp32"):
            raise ValueError(f"--precision {self.precision!r}: choose auto, bf16 or fp32")
        if self.extra and self.task == "depth":
            raise ValueError("--extra: real image folders carry labels, not depth; drop it "
                             "for --task depth")

    @property
    def epochs(self) -> int:
        return sum(n for _, n in self.schedule)

    def learning_rate(self, epoch: int) -> float:
        for lr, n in self.schedule:
            if epoch < n:
                return lr
            epoch -= n
        return self.schedule[-1][0]


def parse_schedule(text: str) -> tuple[tuple[float, int], ...]:
    try:
        return tuple((float(lr), int(n)) for lr, n in
                     (stage.split(":") for stage in text.split(",")))
    except ValueError:
        raise ValueError(f"--schedule {text!r}: write LR:EPOCHS stages separated by commas, "
                         "e.g. 1e-3:200,1e-4:50,1e-5:10") from None


def settings_from_json(data: dict) -> TrainSettings:
    data = {**data, "extra": tuple(data["extra"]), "image_size": tuple(data["image_size"]),
            "schedule": tuple(tuple(s) for s in data["schedule"])}
    return TrainSettings(**data)


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def bf16_helps(device: torch.device) -> bool:
    """Whether bf16 autocast runs natively. On a CPU without AVX512-BF16 or AMX it is emulated
    and an FCN58 training step ran 16x slower than fp32 (AVX2 EPYC; bench/bench_train.py)."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    return "avx512_bf16" in flags or "amx_bf16" in flags


def use_bf16(precision: str, device: torch.device) -> bool:
    return precision == "bf16" or (precision == "auto" and bf16_helps(device))


# --- data ------------------------------------------------------------------------------------
def training_sets(s: TrainSettings) -> tuple[Dataset, Dataset]:
    """(train, validation): the training split minus a seeded random validation part of its
    views; the plates (damage) and extra real folders stay in training."""
    split = TokaidoDataset(s.data, "train", s.task, views=s.views, image_size=s.image_size,
                           puretex=s.task == "damage" and s.puretex)
    frames = [i for i, r in enumerate(split.items) if isinstance(r, FrameRecord)]
    if not frames:
        raise ValueError(f"--data {s.data!r} has no training images for task {s.task!r}")
    n_val = min(s.val_count, len(frames) // 5)
    order = np.random.default_rng(np.random.SeedSequence([s.seed, 1])).permutation(len(frames))
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
        return berhu(output[:, 0], target)
    return weighted_cross_entropy(output, target, weights)


def predict_ids(task: str, output: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """Ids 1..K from logits. Components: argmax of the softmax divided by the MFB weights
    (paper Section 4.4); classes with weight 0 (absent in training) are never chosen.
    Damage: plain argmax."""
    output = output.float()
    if task == "component" and weights is not None:
        w = weights.to(output.device).view(1, -1, 1, 1)
        probs = torch.softmax(output, 1)
        output = torch.where(w > 0, probs / w.clamp_min(1e-12), torch.full_like(probs, -1.0))
    return output.argmax(1) + 1


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
def save_torch(path: Path, data: dict) -> None:
    buffer = io.BytesIO()
    torch.save(data, buffer)
    atomic_write_bytes(path, buffer.getvalue())


def load_torch(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)


def _distributed() -> tuple[int, int]:
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


def open_run(run: Path, settings: TrainSettings) -> dict | None:
    """Create a run folder, or reopen one with the same settings; returns its checkpoint."""
    stored = run / "settings.json"
    if stored.exists():
        previous = settings_from_json(json.loads(stored.read_text()))
        if previous != settings:
            raise ValueError(f"--out {str(run)!r} holds a run with other settings; use a new "
                             "folder, or the same options to resume it")
        checkpoint = run / "checkpoint.pt"
        return load_torch(checkpoint) if checkpoint.exists() else None
    if run.exists() and any(run.iterdir()):
        raise ValueError(f"--out {str(run)!r} is not empty and holds no training run")
    atomic_write_json(stored, dataclasses.asdict(settings))
    return None


def train(settings: TrainSettings, run: str | Path, log=print) -> dict:
    """Train (or resume) a run; returns the final history entry."""
    run = Path(run)
    rank, world = _distributed()
    device = pick_device(settings.device)
    if device.type == "cuda" and world > 1:
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    checkpoint = open_run(run, settings) if rank == 0 else None
    if world > 1:
        torch.distributed.barrier()
        if rank:
            path = run / "checkpoint.pt"
            checkpoint = load_torch(path) if path.exists() else None
    train_set, val_set = training_sets(settings)
    weights = None
    if settings.task != "depth":
        stats_file = run / "class_weights.json"
        if stats_file.exists():
            stats = json.loads(stats_file.read_text())
        else:
            stats = class_statistics(train_set, N_OUTPUTS[settings.task])
            if rank == 0:
                atomic_write_json(stats_file, {"classes": CLASS_NAMES[settings.task], **stats})
        weights = torch.tensor(stats["weights"], dtype=torch.float32, device=device)
    torch.manual_seed(settings.seed)
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
    bf16 = use_bf16(settings.precision, device)

    def autocast():
        return torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16)

    loader_options = dict(batch_size=settings.batch_size, num_workers=settings.loader_workers,
                          pin_memory=device.type == "cuda",
                          persistent_workers=settings.loader_workers > 0)
    val_loader = DataLoader(val_set, shuffle=False, **loader_options) if len(val_set) else None
    started = time.perf_counter()
    spent = float(history[-1]["train_seconds_total"]) if history else 0.0
    stopped = False
    for epoch in range(start_epoch, settings.epochs):
        for group in optimizer.param_groups:
            group["lr"] = settings.learning_rate(epoch)
        generator = torch.Generator().manual_seed(settings.seed * 100_003 + epoch)
        order = torch.randperm(len(train_set), generator=generator).tolist()
        shard = order[rank::world][:len(order) // world] if world > 1 else order
        loader = DataLoader(Subset(train_set, shard), shuffle=False, drop_last=False,
                            **{**loader_options, "persistent_workers": False})
        net.train()
        t0, losses, images_seen = time.perf_counter(), [], 0
        for images, targets in loader:
            images, targets = flip_batch(images, targets, generator)
            images = prepare(images, device, settings.channels_last)
            targets = targets.to(device, non_blocking=True)
            with autocast():
                output = net(images)
            loss = task_loss(settings.task, output, targets, weights)
            value = loss.detach().item()
            if not math.isfinite(value):
                raise FloatingPointError(f"training loss became {value} at epoch "
                                         f"{epoch + 1}; lower the learning rate or use "
                                         "--precision fp32")
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            losses.append(value)
            images_seen += images.shape[0]
            if settings.time_budget_s is not None and _all_agree(
                    spent + time.perf_counter() - started > settings.time_budget_s, world, device):
                stopped = True
                break
        seconds = time.perf_counter() - t0
        entry = {"epoch": epoch + 1, "lr": settings.learning_rate(epoch),
                 "precision": "bf16" if bf16 else "fp32",
                 "train_loss": float(np.mean(losses)) if losses else None,
                 "images": images_seen * world, "seconds": round(seconds, 3),
                 "images_per_s": round(images_seen * world / seconds, 3) if seconds else None}
        if val_loader is not None:
            entry.update(validate(model, val_loader, settings.task, weights, device, autocast,
                                  settings.channels_last))
        spent += time.perf_counter() - started
        started = time.perf_counter()
        entry["train_seconds_total"] = round(spent, 3)
        history.append(entry)
        if rank == 0:
            save_torch(run / "checkpoint.pt",
                       {"model": model.state_dict(), "optimizer": optimizer.state_dict(),
                        "epoch": epoch + 1, "history": history, "stopped_by_budget": stopped})
            atomic_write_json(run / "history.json", history)
            plot_curves(history, run / "curves.png", settings.task)
            log(json.dumps(entry))
        if stopped:
            break
    if rank == 0:
        save_torch(run / "model.pt", {
            "task": settings.task, "out_channels": N_OUTPUTS[settings.task],
            "image_size": list(settings.image_size),
            "target_size": list(target_size(settings.image_size)),
            "mfb_weights": weights.cpu() if weights is not None else None,
            "state_dict": model.state_dict()})
    if world > 1:
        torch.distributed.barrier()
    return history[-1] if history else {}


def plot_curves(history: list[dict], path: Path, task: str) -> None:
    from glsynth.core.plots import save_figure
    import matplotlib.pyplot as plt

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
