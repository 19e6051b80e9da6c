"""Making the built-in texture repository (its first use on a machine): one thread against
BUILD_THREADS, and whether both give the same bytes.

Each round makes the repository afresh in a temporary folder, once on one thread and once on
BUILD_THREADS, taking turns; medians over the rounds. The settings are the default config's
(seed 0, 12 images a category, 1024 px) unless given.

    .venv/bin/python bench/bench_repository.py [--rounds 3] [--count 12] [--size 1024]
"""

import argparse
import hashlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.appearance import repository  # noqa: E402
from glsynth.appearance.texgen import CATEGORIES  # noqa: E402


def _made(threads: int, count: int, size: int) -> tuple[float, str]:
    """Seconds to make the repository on ``threads``, and a digest of its files."""
    repository.BUILD_THREADS = threads
    with tempfile.TemporaryDirectory() as folder:
        t0 = time.perf_counter()
        root = repository.generate_repository(Path(folder) / "repo", 0, count, size)
        seconds = time.perf_counter() - t0
        digest = hashlib.sha256()
        for path in sorted(root.rglob("*.png")):
            digest.update(path.name.encode() + path.read_bytes())
    return seconds, digest.hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--count", type=int, default=12, help="images a category")
    parser.add_argument("--size", type=int, default=1024, help="pixels")
    args = parser.parse_args()
    many = repository.BUILD_THREADS
    times: dict[int, list[float]] = {1: [], many: []}
    digests = set()
    for _ in range(args.rounds):
        for threads in (1, many):
            seconds, digest = _made(threads, args.count, args.size)
            times[threads].append(seconds)
            digests.add(digest)
    one, several = (statistics.median(times[t]) for t in (1, many))
    write_results("repository", {
        "images": len(CATEGORIES) * args.count, "size_px": args.size, "rounds": args.rounds,
        "seconds": {str(t): v for t, v in times.items()},
        "median_s": {"1": one, str(many): several}, "ratio": several / one,
        "same_bytes": len(digests) == 1})


if __name__ == "__main__":
    main()
