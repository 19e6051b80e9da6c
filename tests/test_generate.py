"""Dataset generation end to end at the Tokaido format size (1920x1080 images, 640x360 maps)
on a tiny configuration: format compliance, resume after a kill, worker-count independence.
The tests that rerun a whole generation compare it with conftest's quick dataset (QUICK: 2
environments of 2 cameras, a plate, cheap shadows and sky maps), so each rerun costs little."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from glsynth.cli import main
from glsynth.core.errors import UserError
from glsynth.core.labels import COMPONENT_IDS, DAMAGE_IDS
from glsynth.data.tokaido import read_manifest


def generate(config, out, *extra) -> int:
    return main(["generate", "--preset", "demo", "--config", str(config), "--seed", "5",
                 "--out", str(out), *extra])


def dataset_files(root: Path) -> dict[str, str]:
    """Everything that makes up the dataset (report.json holds timings and is left out), as
    sha256 digests: a failed comparison then names the files that differ, where comparing
    bytes would have pytest diff megabytes of image data for many minutes."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != "report.json"}


def test_format_compliance(tiny_dataset):
    root = tiny_dataset
    train = read_manifest(root, "files_train.csv")
    test = read_manifest(root, "files_test.csv")
    assert train and test
    damage_pixels = np.zeros(len(DAMAGE_IDS), np.int64)  # of the damage task's images, by id
    assert all("case0_" in r.image for r in train) and all("case1_" in r.image for r in test)
    for r in train + test:
        image = np.asarray(Image.open(root / r.image))
        assert image.shape == (1080, 1920, 3) and image.dtype == np.uint8
        comp = np.asarray(Image.open(root / r.component))
        dmg = np.asarray(Image.open(root / r.damage))
        depth_im = Image.open(root / r.depth)
        assert comp.shape == dmg.shape == (360, 640) and comp.dtype == dmg.dtype == np.uint8
        assert depth_im.mode in ("I;16", "I;16B") and depth_im.size == (640, 360)
        assert set(np.unique(comp)) <= COMPONENT_IDS - {0}  # class 8: the demo preset draws others
        assert set(np.unique(dmg)) <= DAMAGE_IDS
        assert 15.0 <= r.focal_mm <= 55.0
        assert r.damage_in_rrdr == bool(np.isin(dmg, [2, 3]).any())
        if r.damage_in_rrdr:
            damage_pixels += np.bincount(dmg.ravel(), minlength=len(DAMAGE_IDS))
        index = int(r.image.rsplit("_frame", 1)[1].split("_")[0])
        assert r.regular == (index < 3)
        meta = json.loads((root / "meta" / ("train" if r in train else "test")
                           / Path(r.image).name.replace("_Scene.png", ".json")).read_text())
        assert meta["root_seed"] == 5 and len(meta["camera"]["K"]) == 3
    for line in (root / "files_train.csv").read_text().splitlines():
        assert len(line.split(",")) == 7
    pure = read_manifest(root, "files_puretex_train.csv") + read_manifest(
        root, "files_puretex_test.csv")
    assert len(pure) == 3 and len(read_manifest(root, "files_puretex_test.csv")) == 1
    for r in pure:
        dmg = np.asarray(Image.open(root / r.damage))
        assert dmg.shape == (360, 640)
        damage_pixels += np.bincount(dmg.ravel(), minlength=len(DAMAGE_IDS))
    report = json.loads((root / "report.json").read_text())
    assert report["kept"] == len(train) + len(test)
    stats = report["statistics"]
    removed = sum(sum(r.values()) for r in stats["removed"].values())
    assert report["kept"] + removed == 2 * 5
    assert stats["images"]["regular"] + sum(stats["removed"]["regular"].values()) == 2 * 3
    # The shares of the damage task's labelled pixels, as the label files hold them.
    labelled = damage_pixels[1:].sum()
    assert damage_pixels[2] > 0 and labelled > damage_pixels[2:].sum()
    assert stats["damage_share"] == {"concrete": pytest.approx(damage_pixels[2] / labelled),
                                     "rebar": pytest.approx(damage_pixels[3] / labelled)}
    assert (root / "contact_sheet.png").stat().st_size > 1000


def test_same_dataset_with_two_workers(quick_config, quick_dataset, tmp_path):
    out = tmp_path / "ds"
    assert generate(quick_config, out, "--workers", "2") == 0
    assert dataset_files(out) == dataset_files(quick_dataset)
    peaks = json.loads((out / "report.json").read_text())["worker_peak_rss_mib"]
    assert 1 <= len(peaks) <= 2 and all(p > 50 for p in peaks)  # one entry per worker process


def test_ray_engine_locally_gives_the_same_dataset(quick_config, quick_dataset, tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "ds"
    assert generate(quick_config, out, "--engine", "ray", "--workers", "2") == 0
    assert dataset_files(out) == dataset_files(quick_dataset)
    assert json.loads((out / "report.json").read_text())["engine"] == "ray"


def test_ray_cluster_of_two_nodes_gives_the_same_dataset(quick_config, quick_dataset, tmp_path):
    """The cluster path (--address) on two Ray nodes of this machine, one CPU each, so the two
    actors run on different nodes, as they would on two machines sharing the output folder."""
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        out = tmp_path / "ds"
        assert generate(quick_config, out, "--engine", "ray", "--address", cluster.address,
                        "--workers", "2") == 0
        assert dataset_files(out) == dataset_files(quick_dataset)
        report = json.loads((out / "report.json").read_text())
        assert report["engine"] == "ray" and len(report["worker_peak_rss_mib"]) == 2
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_ray_worker_that_cannot_see_the_output_says_so(small_config, tmp_path):
    from glsynth.core.config import load_config
    from glsynth.data.engines import GenerationWorker

    config = load_config("demo", small_config)
    with pytest.raises(UserError, match="shared filesystem"):
        GenerationWorker(config, 5, str(tmp_path / "elsewhere"))


def test_engine_arguments_are_checked(small_config, tmp_path, capsys):
    assert generate(small_config, tmp_path / "a", "--address", "auto") == 2
    assert "--address is for --engine ray" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: --workers takes integers >= 1
        generate(small_config, tmp_path / "b", "--workers", "0")
    assert "--workers: 0: must be an integer in [1, 2**63 - 1]" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()


def test_resume_after_a_kill_gives_the_same_bytes(quick_config, quick_dataset, tmp_path):
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "glsynth", "generate", "--preset", "demo", "--config",
           str(quick_config), "--seed", "5", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    # Kill it in the middle of the second environment: after its first image is written.
    while time.time() < deadline and not list((out / "img_syn_raw" / "test").glob("*.png")):
        time.sleep(0.05)
    assert list((out / "img_syn_raw" / "test").glob("*.png")), "no image within 120 s"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "files_train.csv").exists()
    assert generate(quick_config, out) == 0
    assert dataset_files(out) == dataset_files(quick_dataset)
    assert not list(out.rglob(".*.tmp"))


def test_a_write_that_fails_in_the_writer_ends_the_run_and_resume_completes_it(
        quick_config, quick_dataset, tmp_path, capsys, monkeypatch):
    """Files are encoded and written in a background thread; its first failure ends the run
    with the file's name, the environment gets no marker, and a rerun gives the same bytes."""
    import glsynth.core.fileio as fileio

    real = fileio.atomic_write_json

    def disk_full(path, data):
        if Path(path).name == "image_case1_frame0.json":
            raise UserError(f"cannot write {str(path)!r}: No space left on device")
        real(path, data)

    monkeypatch.setattr(fileio, "atomic_write_json", disk_full)
    out = tmp_path / "ds"
    assert generate(quick_config, out) == 2
    assert "image_case1_frame0.json': No space left" in capsys.readouterr().err
    # Environment 0 (written first) is done; environment 1 is not.
    assert (out / "progress" / "env_000000.json").exists()
    assert not (out / "progress" / "env_000001.json").exists()
    monkeypatch.setattr(fileio, "atomic_write_json", real)
    assert generate(quick_config, out) == 0
    assert dataset_files(out) == dataset_files(quick_dataset)
    assert not list(out.rglob(".*.tmp"))


def test_a_finished_run_does_no_work_twice(quick_config, quick_dataset, tmp_path, capsys):
    import shutil

    out = tmp_path / "ds"
    shutil.copytree(quick_dataset, out)
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*.png")}
    first = json.loads((out / "report.json").read_text())
    assert generate(quick_config, out) == 0
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.png")
            if p.name != "contact_sheet.png"} == {p: t for p, t in before.items()
                                                   if p.name != "contact_sheet.png"}
    # The report keeps the run that made the data beside the one that found nothing to do.
    report = json.loads((out / "report.json").read_text())
    assert report["images_written_this_run"] == 0
    assert [r["wall_s"] for r in report["runs"]] == [first["wall_s"], report["wall_s"]]
    assert report["runs"][0] == first["runs"][0] and first["runs"][0]["wall_s"] > 0
    assert report["images_written_all_runs"] == first["images_written_this_run"] > 0
    # A broken report is refused with one line, before any work (glsynth.data.report).
    (out / "report.json").write_text("{truncated")
    assert generate(quick_config, out) == 2
    assert "report.json' is not valid JSON" in capsys.readouterr().err


def test_bad_outputs_are_clear_errors(quick_config, quick_dataset, tmp_path, capsys):
    other = tmp_path / "full"
    other.mkdir()
    (other / "x.txt").write_text("x")
    assert generate(quick_config, other) == 2
    assert "is not empty and holds no glsynth run" in capsys.readouterr().err
    assert main(["generate", "--preset", "demo", "--config", str(quick_config), "--seed", "6",
                 "--out", str(quick_dataset)]) == 2
    assert "holds a run with other settings" in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert generate(quick_config, blocker / "ds") == 2
    assert "Choose a writable --out" in capsys.readouterr().err


def test_pytorch_dataset_reads_the_generated_layout(tiny_dataset):
    import torch
    from glsynth.model.data import TokaidoDataset

    comp = TokaidoDataset(tiny_dataset, "train", "component", image_size=(960, 540))
    assert len(comp) == sum(r.regular for r in read_manifest(tiny_dataset, "files_train.csv"))
    image, target = comp[0]
    assert image.shape == (3, 540, 960) and image.dtype == torch.float32
    assert 0.0 <= float(image.min()) and float(image.max()) <= 1.0
    assert target.shape == (180, 320) and target.dtype == torch.int64
    depth = TokaidoDataset(tiny_dataset, "test", "depth")
    _, d = depth[0]
    assert d.shape == (360, 640) and d.dtype == torch.float32
    # A regular view stands 1-10 m above ground and 10 m from the track: it sees geometry
    # nearer than the 30 m clip, and nothing nearer than the 0.5 m one.
    assert float(d.min()) > 0.5 and (d < 30.0).any()
    dmg = TokaidoDataset(tiny_dataset, "train", "damage", puretex=True)
    flagged = [r for r in read_manifest(tiny_dataset, "files_train.csv") if r.damage_in_rrdr]
    assert len(dmg) == len(flagged) + 2
    _, labels = dmg[len(dmg) - 1]  # a plate
    assert set(labels.unique().tolist()) <= {1, 2, 3}
    odd = TokaidoDataset(tiny_dataset, "train", "component", image_size=(640, 360))
    assert odd[0][1].shape == (120, 214)  # FCN58's ceil(H/3) x ceil(W/3)
    with pytest.raises(ValueError, match="puretex"):
        TokaidoDataset(tiny_dataset, task="depth", puretex=True)
