"""FCN58 training throughput on this machine: images per second of the real training loop
(data loading, flips, bf16 autocast, channels_last, Adam) at 640x360 and 1920x1080, batch 8,
next to the bare step on tensors already in memory.

    .venv/bin/python bench/bench_train.py [--data out/demo/dataset] [--steps 4]

Re-executes itself with Debian's jemalloc preloaded (docs/design.md, "Training memory") unless
--no-jemalloc; the results say which allocator ran.
"""

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import JEMALLOC, training_env, write_results  # noqa: E402

SIZES = ((642, 360), (1920, 1080))  # 642: a multiple of 3 near 640, so targets are exact


def bare_steps(size: tuple[int, int], steps: int, bf16: bool) -> float:
    """Median seconds per image of forward + backward + Adam on a fixed batch of 8."""
    import torch
    from glsynth.model.fcn58 import FCN58
    from glsynth.model.losses import weighted_cross_entropy

    model = FCN58(8).to(memory_format=torch.channels_last)
    optimizer = torch.optim.Adam(model.parameters(), 1e-3, weight_decay=1e-4)
    w, h = size
    images = torch.rand(8, 3, h, w).contiguous(memory_format=torch.channels_last)
    labels = torch.randint(0, 9, (8, -(-h // 3), -(-w // 3)))
    times = []
    for i in range(steps + 1):
        t0 = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out = model(images)
        loss = weighted_cross_entropy(out, labels, torch.ones(8))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if i:
            times.append((time.perf_counter() - t0) / 8)
    return statistics.median(times)


def loop_rate(data: Path, size: tuple[int, int]) -> tuple[float, int]:
    """Images per second of glsynth's training loop over the dataset's training images: the
    second of two epochs (the first pays for oneDNN's kernel set-up)."""
    from glsynth.model.settings import TrainSettings
    from glsynth.model.train import train

    with tempfile.TemporaryDirectory() as tmp:
        settings = TrainSettings(task="component", data=str(data), image_size=size,
                                 schedule=((1e-3, 2),), val_count=0, loader_workers=1)
        last = train(settings, Path(tmp) / "run", log=lambda line: None)
    return last["images_per_s"], last["images"]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--data", default="out/demo/dataset")
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--no-jemalloc", action="store_true")
    args = parser.parse_args()
    if not args.no_jemalloc and JEMALLOC not in os.environ.get("LD_PRELOAD", "") and \
            Path(JEMALLOC).exists():
        os.execve(sys.executable, [sys.executable, *sys.argv], training_env())
    data = Path(args.data)
    if not (data / "files_train.csv").exists():
        sys.exit(f"--data {data}: no dataset there; run bash scripts/setup.sh first")
    import torch
    from glsynth.model.runtime import bf16_helps

    native = bf16_helps(torch.device("cpu"))
    results = {"allocator": "jemalloc" if JEMALLOC in os.environ.get("LD_PRELOAD", "")
               else "glibc", "batch": 8, "channels_last": True,
               "cpu_capability": torch.backends.cpu.get_cpu_capability(),
               "native_bf16": native, "loop_precision": "bf16" if native else "fp32"}
    for size in SIZES:
        step = bare_steps(size, args.steps, native)
        rate, images = loop_rate(data, size)
        results[f"{size[0]}x{size[1]}"] = {
            "training_images_per_epoch": images,
            "bare_step_s_per_image": round(step, 4),
            "bare_step_bf16_emulated_s_per_image": None if native else
            round(bare_steps(size, 2, True), 4) if size[0] < 1000 else None,
            "training_loop_images_per_s": rate,
            "training_loop_s_per_image": round(1 / rate, 4),
            "loop_over_bare": round(1 / rate / step, 2)}
    write_results("train", results)


if __name__ == "__main__":
    main()
