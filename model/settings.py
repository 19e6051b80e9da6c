"""Training settings, tasks and sizes: plain data without torch, so that the command line can
build its options from them without importing torch."""

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from glsynth.core.errors import UserError
from glsynth.core.labels import LABEL_MAPS
from glsynth.core.options import parse_size
from glsynth.data.tokaido import IMAGE_SIZE

CLASS_NAMES = {task: [label.name.lower() for label in labels if label]
               for task, labels in LABEL_MAPS.items()}
"""Class names of the label tasks, by id 1..K (0, unlabelled, is never predicted)."""
TASKS = (*CLASS_NAMES, "depth")
N_OUTPUTS = {**{task: len(names) for task, names in CLASS_NAMES.items()}, "depth": 1}
"""Network output channels per task: ids 1..8 (components), 1..3 (damage), metres (depth)."""
VIEWS = ("regular", "closeup", "all")
PRECISIONS = ("auto", "bf16", "fp32")
PAPER_SCHEDULE = ((1e-3, 200), (1e-4, 50), (1e-5, 10))
MIN_SIDE = 96
"""FCN58's smallest input side: /3, /2 and four 2x2 pools leave one pixel at the deepest scale."""


def target_size(image_size: tuple[int, int]) -> tuple[int, int]:
    """(width, height) of FCN58's output and of the targets: a third, rounded up."""
    return (-(-image_size[0] // 3), -(-image_size[1] // 3))


def _image_size(text: str) -> tuple[int, int]:
    """'WxH' -> (W, H), each side at least FCN58's MIN_SIDE."""
    return parse_size(text, MIN_SIDE)


AUGMENTATIONS = ("exposure", "white_balance", "blur", "noise", "jpeg")
"""Photometric augmentations of glsynth.model.augment, in a canonical order (the module applies
them in a camera's order, whatever the order given)."""


def parse_augment(text: str) -> tuple[str, ...]:
    """'all', 'none' or a comma list of AUGMENTATIONS -> the chosen ones, in canonical order."""
    names = {n.strip() for n in text.split(",") if n.strip()}
    if names == {"all"}:
        return AUGMENTATIONS
    if names <= {"none"}:
        return ()
    unknown = sorted(names - set(AUGMENTATIONS))
    if unknown:
        raise UserError(f"--augment {text!r}: unknown {', '.join(unknown)}; give all, none or "
                        f"a comma list of {', '.join(AUGMENTATIONS)}")
    return tuple(a for a in AUGMENTATIONS if a in names)


def parse_schedule(text: str) -> tuple[tuple[float, int], ...]:
    """'1e-3:200,1e-4:50' -> ((0.001, 200), (0.0001, 50))."""
    try:
        return tuple((float(lr), int(n)) for lr, n in
                     (stage.split(":") for stage in text.split(",")))
    except ValueError:
        raise UserError(f"--schedule {text!r}: write LR:EPOCHS stages separated by commas, "
                        "e.g. 1e-3:200,1e-4:50,1e-5:10") from None


def _folder(text: str) -> str:
    return str(Path(text).resolve())


@dataclass(frozen=True)
class TrainSettings:
    # Literal[tuple] is Literal of the tuple's items: the command line's choices come from
    # these types (glsynth.core.options), so each list of values is written once, above.
    task: Literal[TASKS]
    """Which network: component labels, damage labels or depth."""
    data: str = field(metadata={"parse": _folder, "metavar": "DIR"})
    """Tokaido-layout dataset root (glsynth's output or the released dataset)."""
    extra: tuple[str, ...] = field(default=(), metadata={"parse": _folder, "repeat": True,
                                                          "metavar": "DIR"})
    """Folders of real labelled photos mixed into training: DIR/images/* and
    DIR/labels/<stem>.png (repeatable)."""
    image_size: tuple[int, int] = field(default=IMAGE_SIZE, metadata={
        "parse": _image_size, "metavar": "WxH", "show": "x".join(map(str, IMAGE_SIZE))})
    """Input size images are resized to; targets are a third, rounded up."""
    batch_size: int = 8
    """Images per step (paper: 8)."""
    schedule: tuple[tuple[float, int], ...] = field(default=PAPER_SCHEDULE, metadata={
        "parse": parse_schedule, "metavar": "LR:EPOCHS,...", "show": "1e-3:200,1e-4:50,1e-5:10"})
    """Learning-rate stages (paper Section 4.3)."""
    weight_decay: float = 1e-4
    """Adam's weight decay (paper: 1e-4)."""
    val_count: int = 300
    """Training images held out for validation (at most a fifth of them)."""
    puretex: bool = True
    """Damage task: add the pure-texture plates to training."""
    augment: tuple[str, ...] = field(default=(), metadata={
        "parse": parse_augment, "metavar": "all|none|exposure,white_balance,blur,noise,jpeg",
        "show": "none"})
    """Photometric augmentations of training images (glsynth.model.augment), drawn per image on
    the training device; off by default, as the paper used flips only."""
    seed: int = 0
    """Seed of the validation split, the initial weights, shuffling and flips."""
    precision: Literal[PRECISIONS] = "auto"
    """bf16 autocast, fp32, or auto: bf16 only where the hardware runs it natively."""
    channels_last: bool = True
    """NHWC memory layout (faster on CPUs and GPUs)."""
    loader_workers: int = 1
    """Processes decoding images."""
    cache_inputs: bool = field(default=False, compare=False)
    """Keep training images resized to image_size under $GLSYNTH_CACHE/inputs (uint8 .npz,
    W x H x 3 bytes each: 0.39 MB at 480x270, 6.2 MB at 1920x1080), so epochs after the
    first decode no PNG. The tensors are the same as without it."""
    time_budget_min: float | None = None
    """Stop after the step that passes this many minutes of training (then validate, save)."""
    views: Literal[VIEWS] | None = None
    """Camera kinds to train on; default regular for component/depth, all for damage."""
    device: str = field(default="auto", compare=False)
    """auto, cpu, cuda or cuda:N."""

    def __post_init__(self) -> None:
        self._check_choices()
        for name, lo in (("batch_size", 1), ("val_count", 0), ("loader_workers", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < lo:
                raise UserError(f"--{name.replace('_', '-')} {value}: give an integer >= {lo}")
        if not self.schedule or any(not 0 < lr < math.inf or n < 1 for lr, n in self.schedule):
            raise UserError(f"--schedule {self.schedule}: give LR:EPOCHS stages with finite "
                            "LR > 0 and EPOCHS >= 1, e.g. 1e-3:200,1e-4:50,1e-5:10")
        if not 0 <= self.weight_decay < math.inf:
            raise UserError(f"--weight-decay {self.weight_decay}: give a finite number >= 0")
        if self.time_budget_min is not None and not 0 < self.time_budget_min < math.inf:
            raise UserError(f"--time-budget-min {self.time_budget_min}: give finite minutes > 0")
        unknown = [a for a in self.augment if a not in AUGMENTATIONS]
        if unknown:
            raise UserError(f"--augment {','.join(self.augment)}: unknown {', '.join(unknown)}; "
                            f"choose from {', '.join(AUGMENTATIONS)}")
        if self.extra and self.task == "depth":
            raise UserError("--extra: real image folders carry labels, not depth; drop it "
                            "for --task depth")

    def _check_choices(self) -> None:
        """Each Literal-typed field holds one of its values: the command line allows only
        those, but a caller or a settings.json may give anything."""
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            choices = [c for t in (hints[f.name], *typing.get_args(hints[f.name]))
                       if typing.get_origin(t) is Literal for c in typing.get_args(t)]
            if choices and value is not None and value not in choices:
                raise UserError(f"--{f.name.replace('_', '-')} {value!r}: choose one of "
                                f"{', '.join(choices)}")

    @property
    def epochs(self) -> int:
        return sum(n for _, n in self.schedule)

    def learning_rate(self, epoch: int) -> float:
        for lr, n in self.schedule:
            if epoch < n:
                return lr
            epoch -= n
        return self.schedule[-1][0]


def settings_from_json(data: dict[str, Any]) -> TrainSettings:
    """Settings as stored in a run folder's settings.json."""
    known = {f.name for f in dataclasses.fields(TrainSettings)}
    data = {k: v for k, v in data.items() if k in known}
    data.update(extra=tuple(data.get("extra", ())), augment=tuple(data.get("augment", ())),
                image_size=tuple(data["image_size"]),
                schedule=tuple(tuple(s) for s in data["schedule"]))
    return TrainSettings(**data)
