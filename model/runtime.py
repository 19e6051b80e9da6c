"""What training and inference share: the device and whether bf16 pays on it, the torch files
of a run folder (checkpoints and models) and the ids a segmentation network's logits give."""

import io
import os
from pathlib import Path

import torch

from glsynth.core.errors import UserError, named
from glsynth.core.fileio import atomic_write_bytes
from glsynth.core.reading import check_file


def pick_device(name: str) -> torch.device:
    """The device --device names, checked to exist here: auto (CUDA when there is one), cpu,
    cuda or cuda:N."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device(name)
    kind, _, index = name.partition(":")
    if kind != "cuda" or not (index == "" or index.isdigit()):
        raise UserError(f"--device {name!r}: choose auto, cpu, cuda or cuda:N")
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    if int(index or 0) >= count:
        raise UserError(f"--device {name!r}: this machine has {count} CUDA device(s); use "
                        "--device cpu or auto")
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


MAX_CHECKPOINT_BYTES = 1 << 32
"""A generous bound on a checkpoint (the network and its optimiser state)."""


def save_torch(path: Path, data: dict) -> None:
    buffer = io.BytesIO()
    torch.save(data, buffer)
    atomic_write_bytes(path, buffer.getvalue())


def load_torch(path: Path) -> dict:
    """A file written by save_torch; anything else (truncated, foreign, not torch at all) is a
    UserError naming the file, never an invitation to unpickle arbitrary code."""
    if os.path.lexists(path):  # a missing one stays FileNotFoundError, which callers handle
        check_file(path, "checkpoint", MAX_CHECKPOINT_BYTES, "train again into a new --out "
                   "folder")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as err:  # torch raises RuntimeError, UnpicklingError, EOFError, ...
        raise UserError(f"{named(path)} is not a readable glsynth checkpoint "
                        f"({type(err).__name__}); it is damaged or from elsewhere: train "
                        "again into a new --out folder") from err
    if not isinstance(data, dict):
        raise UserError(f"{named(path)} holds {type(data).__name__}, not a glsynth checkpoint")
    return data


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
