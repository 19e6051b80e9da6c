"""The training loader's image path: PNG decoding (Pillow, OpenCV, pyspng), resizing to the
training size (Pillow bilinear, OpenCV INTER_AREA), a hit of the input cache, and the training
loop's images per second with and without the cache.

    .venv/bin/python bench/bench_loader.py --data DATASET [--size 480x270] [--images 12]

DATASET is a glsynth dataset of 1920x1080 views (e.g. out/bench-transfer/gl from
bench_transfer.py). Writes bench/results/loader.json.
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import summary, time_calls, training_env, write_results  # noqa: E402
from glsynth.model.data import InputCache, load_image, read_rgb, resize_rgb  # noqa: E402

from glsynth.data.tokaido import read_manifest  # noqa: E402


def pillow_decode(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def pillow_load(path: Path, size: tuple[int, int]) -> np.ndarray:
    """The loader before OpenCV: Pillow decoding and bilinear resizing."""
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB").resize(size, Image.Resampling.BILINEAR))


def per_image(fn, paths: list[Path]) -> dict:
    times = []
    for p in paths:
        times += time_calls(lambda p=p: fn(p), repeats=3)
    return {k.replace("_s", "_ms"): round(v * 1000, 2) for k, v in summary(times).items()
            if k != "n"}


def loop_rate(data: Path, size: str, cache: bool, cache_dir: Path) -> float:
    """images/s of the second epoch of a 2-epoch component run (the first fills the cache)."""
    with tempfile.TemporaryDirectory() as run:
        env = training_env(GLSYNTH_CACHE=str(cache_dir))
        subprocess.run([sys.executable, "-m", "glsynth", "train", "--task", "component",
                        "--data", str(data), "--out", run, "--image-size", size,
                        "--schedule", "1e-3:2", "--val-count", "0",
                        *(["--cache-inputs"] if cache else [])], check=True, env=env,
                       stdout=subprocess.DEVNULL)
        return json.loads((Path(run) / "history.json").read_text())[-1]["images_per_s"]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--data", required=True)
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--images", type=int, default=12)
    args = parser.parse_args()
    data = Path(args.data)
    size = tuple(int(v) for v in args.size.split("x"))
    paths = [data / r.image for r in read_manifest(data, "files_train.csv")[:args.images]]
    rgb = read_rgb(paths[0])
    results: dict = {"images": len(paths), "source_size": [rgb.shape[1], rgb.shape[0]],
                     "size": list(size), "ms_per_image": {}}
    ms = results["ms_per_image"]
    ms["decode_pillow"] = per_image(pillow_decode, paths)
    ms["decode_opencv"] = per_image(read_rgb, paths)
    try:
        import pyspng

        ms["decode_pyspng"] = per_image(lambda p: pyspng.load(p.read_bytes()), paths)
    except ImportError:
        results["pyspng"] = "not installed (pip install pyspng)"
    ms["resize_pillow_bilinear"] = per_image(
        lambda p: Image.fromarray(rgb).resize(size, Image.Resampling.BILINEAR), paths[:1])
    ms["resize_opencv_area"] = per_image(lambda p: resize_rgb(rgb, size), paths[:1])
    ms["load_before (Pillow decode + bilinear)"] = per_image(lambda p: pillow_load(p, size),
                                                             paths)
    ms["load_now (OpenCV decode + INTER_AREA)"] = per_image(lambda p: load_image(p, size),
                                                            paths)
    with tempfile.TemporaryDirectory() as base:
        cache = InputCache(data, size, base=Path(base))
        for p in paths:
            cache.load(p)
        ms["cache_hit"] = per_image(cache.load, paths)
    with tempfile.TemporaryDirectory() as base:
        results["training_loop_images_per_s"] = {
            "without_cache": loop_rate(data, args.size, False, Path(base)),
            "with_cache": loop_rate(data, args.size, True, Path(base))}
    write_results("loader", results)


if __name__ == "__main__":
    main()
