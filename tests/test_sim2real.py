"""The sim-to-real benchmark: the tolerant crack scores against hand-made masks, the real
folder reader's refusals, and a tiny end-to-end run of glsynth bench sim2real."""

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from glsynth.cli import main
from glsynth.core.errors import UserError
from glsynth.core.seeding import Stream, make_rng
from glsynth.data.crack_folders import CrackImage, read_real_folder, read_synthetic
from glsynth.measure.crack_scores import best_threshold, count, scores


def blank() -> np.ndarray:
    return np.zeros((20, 20), bool)


def test_scores_of_hand_made_masks():
    truth, predicted = blank(), blank()
    truth[2:12, 5] = True                 # 10 true crack pixels
    predicted[2:12, 6] = True             # 10 pixels 1 px off: near
    predicted[2:7, 15] = True             # 5 pixels 10 px off: false
    predicted[2:4, 5] = True              # 2 pixels on the truth
    c = count(predicted, truth)
    assert (c.predicted, c.predicted_near_truth, c.truth, c.truth_near_prediction,
            c.intersection, c.union) == (17, 12, 10, 10, 2, 25)
    s = scores(c)
    assert s["precision"] == pytest.approx(12 / 17)
    assert s["recall"] == 1.0
    assert s["f1"] == pytest.approx(24 / 29)
    assert s["iou"] == pytest.approx(2 / 25)


def test_tolerance_is_two_pixels_euclidean():
    truth, predicted = blank(), blank()
    truth[10, 10] = True
    predicted[10, 12] = True              # 2 px: counts
    predicted[11, 12] = True              # sqrt(5) px: does not
    s = scores(count(predicted, truth))
    assert (s["precision"], s["recall"], s["f1"], s["iou"]) == (0.5, 1.0, pytest.approx(2 / 3),
                                                                 0.0)


def test_empty_prediction_and_truth_score_zero():
    s = scores(count(blank(), blank()))
    assert s == {"precision": 0.0, "recall": 0.0, "f1": 0.0, "iou": 0.0}


def test_best_single_threshold_over_the_set():
    truths, probs = [], []
    for column in (4, 9):
        truth = blank()
        truth[:, column] = True
        prob = np.where(truth, 0.9, 0.0).astype(np.float32)
        prob[:10, 17] = 0.3               # false cracks that only low thresholds keep
        truths.append(truth)
        probs.append(prob)
    best = best_threshold(probs, truths)
    assert best == {"threshold": 0.5, "precision": 1.0, "recall": 1.0, "f1": 1.0, "iou": 1.0}
    low = best_threshold(probs, truths, thresholds=(0.2,))
    assert low["precision"] == pytest.approx(40 / 60) and low["recall"] == 1.0


def write_real(root, names=("a", "b"), size=(40, 32), mask_size=None, mask_values=255,
               mask_suffix=".png"):
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    for i, name in enumerate(names):
        image = np.full((size[1], size[0], 3), 120 + i, np.uint8)
        mask = np.zeros((mask_size or size)[::-1], np.uint8)
        mask[5:9, 3:30] = mask_values
        cv2.imwrite(str(root / "images" / f"{name}.jpg"), image)
        cv2.imwrite(str(root / "masks" / f"{name}{mask_suffix}"), mask)
    return root


def test_real_folder_reads_masks_of_both_conventions(tmp_path):
    for values, suffix in ((1, ".png"), (255, ".png"), (255, ".jpg")):
        images = read_real_folder(write_real(tmp_path / f"{values}{suffix}", mask_values=values,
                                             mask_suffix=suffix))
        assert [im.name for im in images] == ["a", "b"]
        assert images[0].rgb.shape == (32, 40, 3)
        drawn = np.zeros((32, 40), bool)
        drawn[5:9, 3:30] = True
        assert np.array_equal(images[0].crack, drawn), suffix  # JPEG's ringing binarised away


def test_a_crack_free_jpeg_mask_is_all_background(tmp_path):
    root = write_real(tmp_path / "real", names=("a",))
    cv2.imwrite(str(root / "images" / "b.jpg"), np.full((32, 40, 3), 90, np.uint8))
    cv2.imwrite(str(root / "masks" / "b.jpg"), np.zeros((32, 40), np.uint8))
    a, b = read_real_folder(root)
    assert a.crack.sum() == 4 * 27 and b.name == "b" and not b.crack.any()


@pytest.mark.parametrize("damage, words", [
    ("no folder", "does not exist"),
    ("no masks", "has no masks/ sub-folder"),
    ("no images", "holds no images"),
    ("mask missing", "has no counterpart in masks/"),
    ("image missing", "has no counterpart in images/"),
    ("mask size", "is 20x16 but its image is 40x32"),
    ("unreadable", "is not a readable image"),
    ("0/1 JPEG mask", "is a JPEG whose values reach only 1"),
    ("no crack", "marks a crack pixel; mark cracks at 1 or 255"),
    ("two names", "share a name; keep one of them"),
])
def test_real_folder_refusals_are_one_line(tmp_path, damage, words):
    root = tmp_path / "real"
    if damage == "mask size":
        write_real(root, mask_size=(20, 16))
    elif damage == "0/1 JPEG mask":
        write_real(root, mask_values=1, mask_suffix=".jpg")
    elif damage == "no crack":
        write_real(root, mask_values=0)
    elif damage != "no folder":
        write_real(root)
    if damage == "no masks":
        for p in (root / "masks").iterdir():
            p.unlink()
        (root / "masks").rmdir()
    elif damage == "no images":
        for p in (root / "images").iterdir():
            p.unlink()
    elif damage == "mask missing":
        (root / "masks" / "b.png").unlink()
    elif damage == "image missing":
        (root / "images" / "a.jpg").unlink()
    elif damage == "unreadable":
        (root / "images" / "a.jpg").write_bytes(b"not a jpeg")
    elif damage == "two names":
        (root / "masks" / "a.JPG").write_bytes((root / "masks" / "a.png").read_bytes())
    with pytest.raises(UserError) as err:
        read_real_folder(root)
    assert words in str(err.value) and "\n" not in str(err.value)


TINY = """
[dataset]
n_environments = 1
n_test_environments = 0
[cameras]
n_closeup = 3
"""


@pytest.fixture(scope="module")
def tiny_inspection(tmp_path_factory):
    """An inspection-preset dataset of 3 views (seed 0, environment 0)."""
    root = tmp_path_factory.mktemp("insp")
    (root / "tiny.toml").write_text(TINY)
    out = root / "ds"
    assert main(["generate", "--preset", "inspection", "--config", str(root / "tiny.toml"),
                 "--seed", "0", "--out", str(out)]) == 0
    return out


@pytest.mark.slow  # generates a dataset and trains
def test_sim2real_runs_end_to_end(tiny_inspection, tmp_path, capsys):
    frames = read_synthetic(tiny_inspection)
    assert frames and any(f.crack.any() for f in frames)
    assert frames[0].rgb.shape[:2] == frames[0].crack.shape == (360, 640)
    # A stand-in "real" folder: crops of the renders, with their cracks as masks.
    real = tmp_path / "real"
    (real / "images").mkdir(parents=True)
    (real / "masks").mkdir()
    for k, frame in enumerate(frames):
        for j, left in enumerate((0, 320)):
            name = f"{k}_{j}"
            cv2.imwrite(str(real / "images" / f"{name}.png"), frame.rgb[:, left:left + 320, ::-1])
            cv2.imwrite(str(real / "masks" / f"{name}.png"),
                        frame.crack[:, left:left + 320].astype(np.uint8) * 255)
    out = tmp_path / "bench"

    def argv(folder):
        return ["bench", "sim2real", "--synthetic", str(tiny_inspection), "--real", str(real),
                "--out", str(folder), "--steps", "6", "--crop", "64", "--batch", "2",
                "--width", "4", "--repeats", "1"]

    assert main(argv(out)) == 0
    assert "trained on ds " in capsys.readouterr().out
    result = json.loads((out / "sim2real.json").read_text())
    assert set(result["networks"]) == {"ds", "real"}  # the dataset's folder names its network
    assert result["device"] == "cpu" and result["settings"]["device"] == "auto"  # no CUDA here
    n = 2 * len(frames)  # the views the filters kept, two crops each; 30 % of them tested
    assert result["test_images"] == min(n - 1, max(1, round(0.3 * n)))
    assert result["real_train_images"] == n - result["test_images"]
    for s in result["networks"].values():
        assert 0 <= s["f1"] <= 1 and 0 <= s["iou"] <= 1 and 0.05 <= s["threshold"] <= 0.95
        assert np.isfinite(s["last_loss"])
    picture = cv2.imread(str(out / "predictions.png"))
    assert picture.shape[1] == 4 * 320
    # The same seeds give the same run; a group of every image, scored on the held-out ones,
    # scores what the whole test set does, and changes no network.
    groups = tmp_path / "groups.json"
    groups.write_text(json.dumps({"every": [p.name for p in (real / "images").iterdir()]}))
    assert main(argv(tmp_path / "again") + ["--groups", str(groups)]) == 0
    again = json.loads((tmp_path / "again" / "sim2real.json").read_text())
    assert again["groups"] == {"every": result["test_images"]}
    for name, s in again["networks"].items():
        every = s.pop("groups")["every"]
        assert every == {k: s[k] for k in every}
        assert {k: v for k, v in s.items() if k != "train_s"} == \
            {k: v for k, v in result["networks"][name].items() if k != "train_s"}


def test_sim2real_bad_options_are_one_line(tmp_path, capsys):
    assert main(["bench", "sim2real", "--synthetic", str(tmp_path), "--real",
                 str(tmp_path / "none"), "--out", str(tmp_path / "o"), "--crop", "60"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--crop 60: must be a multiple of 8" in err and "\n" not in err
    assert main(["bench", "sim2real", "--synthetic", str(tmp_path / "a" / "ds"),
                 str(tmp_path / "b" / "ds"), "--real", str(tmp_path), "--out",
                 str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "different folder names" in err and "\n" not in err
    # A device this machine lacks, before any folder is read (the real one does not exist).
    assert main(["bench", "sim2real", "--synthetic", str(tmp_path / "ds"), "--real",
                 str(tmp_path / "none"), "--out", str(tmp_path / "o"), "--device",
                 "cuda:7"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--device 'cuda:7'" in err and "\n" not in err and not (tmp_path / "o").exists()


def crops_folder(root, frames, lefts):
    """A stand-in real folder: 320 px wide crops of the renders at ``lefts``, their cracks as
    masks."""
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    for k, frame in enumerate(frames):
        for left in lefts:
            name = f"{k}_{left}"
            cv2.imwrite(str(root / "images" / f"{name}.png"), frame.rgb[:, left:left + 320, ::-1])
            cv2.imwrite(str(root / "masks" / f"{name}.png"),
                        frame.crack[:, left:left + 320].astype(np.uint8) * 255)
    return root


@pytest.mark.slow  # generates a dataset and trains
def test_sim2real_other_real_folders_on_a_test_only_folder(tiny_inspection, tmp_path, capsys):
    frames = read_synthetic(tiny_inspection)
    real = crops_folder(tmp_path / "real", frames, (0,))       # too few to split: all tested
    other = crops_folder(tmp_path / "pavement", frames, (320,))
    out = tmp_path / "bench"
    assert main(["bench", "sim2real", "--synthetic", str(tiny_inspection), "--real", str(real),
                 "--other-real", str(other), "--test-share", "1", "--out", str(out),
                 "--steps", "6", "--crop", "64", "--batch", "2", "--width", "4",
                 "--repeats", "1"]) == 0
    console = capsys.readouterr().out
    assert "trained on pavement " in console and "other real folder, whole" in console
    assert f"no network trained on the real folder: --test-share 1 tests on all {len(frames)}" \
        in console
    result = json.loads((out / "sim2real.json").read_text())
    assert list(result["networks"]) == ["ds", "pavement"]  # and none named "real"
    assert result["test_images"] == len(frames) and result["real_train_images"] == 0
    assert result["real_trained"] is False and result["other_real"] == [str(other)]
    pavement = result["networks"]["pavement"]
    assert pavement["trained_on"] == "other_real" and pavement["images"] == len(frames)
    assert result["networks"]["ds"]["trained_on"] == "synthetic"
    assert 0 <= pavement["f1"] <= 1 and np.isfinite(pavement["last_loss"])
    picture = cv2.imread(str(out / "predictions.png"))
    assert picture.shape[1] == 4 * 320  # photograph, truth, then the two networks


@pytest.mark.parametrize("damage, words", [
    ("same as real", "--other-real {real}: is the --real folder itself"),
    ("name of real", "none named 'real'"),
    ("name of synthetic", "give folders of different folder names"),
    ("missing", "real folder '{missing}' does not exist"),
    ("test share", "--test-share 1.5: must be in (0, 1]"),
])
def test_sim2real_other_real_refusals_are_one_line(tmp_path, capsys, damage, words):
    """Each refused before any dataset is read or network trained (the synthetic dataset
    given does not exist, so reaching it would say so instead)."""
    real, missing = write_real(tmp_path / "photos"), tmp_path / "missing"
    other = {"same as real": real, "name of real": write_real(tmp_path / "a" / "real"),
             "name of synthetic": write_real(tmp_path / "b" / "ds"), "missing": missing,
             "test share": write_real(tmp_path / "pavement")}[damage]
    argv = ["bench", "sim2real", "--synthetic", str(tmp_path / "ds"), "--real", str(real),
            "--other-real", str(other), "--out", str(tmp_path / "o")]
    assert main(argv + (["--test-share", "1.5"] if damage == "test share" else [])) == 2
    err = capsys.readouterr().err.strip()
    assert words.format(real=real, missing=missing) in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_a_real_folder_of_one_image_is_tested_whole_or_refused(tmp_path):
    from glsynth.model.sim2real import Sim2RealSettings, split_real

    images = read_real_folder(write_real(tmp_path / "one", names=("a",)))
    assert split_real(images, Sim2RealSettings(test_share=1.0)) == ([], images)
    with pytest.raises(UserError, match="or test on all of it with --test-share 1"):
        split_real(images, Sim2RealSettings())


def test_a_stopped_run_keeps_the_networks_it_finished(tmp_path, monkeypatch):
    """sim2real.json is written after each network: stopped during the second, it holds the
    first ("complete" false); run through, all of them ("complete" true)."""
    from glsynth.model import sim2real

    crack = np.zeros((32, 40), bool)
    crack[5:9, 3:30] = True
    rendered = [CrackImage(f"v{i}", np.full((32, 40, 3), 90 + i, np.uint8), crack)
                for i in range(2)]
    monkeypatch.setattr(sim2real, "read_synthetic", lambda path: rendered)
    real, other = write_real(tmp_path / "photos"), write_real(tmp_path / "pavement")
    settings = sim2real.Sim2RealSettings(steps=2, crop=16, batch=2, width=4, test_share=1.0,
                                         repeats=1)
    trained = sim2real.train_network

    def stop_at_second(images, settings, item, device):
        if stop_at_second.calls:
            raise KeyboardInterrupt
        stop_at_second.calls += 1
        return trained(images, settings, item, device)

    stop_at_second.calls = 0
    monkeypatch.setattr(sim2real, "train_network", stop_at_second)
    with pytest.raises(KeyboardInterrupt):
        sim2real.run_sim2real([tmp_path / "ds"], real, tmp_path / "o", settings, [other])
    partial = json.loads((tmp_path / "o" / "sim2real.json").read_text())
    assert list(partial["networks"]) == ["ds"] and partial["complete"] is False
    monkeypatch.setattr(sim2real, "train_network", trained)
    whole = sim2real.run_sim2real([tmp_path / "ds"], real, tmp_path / "o", settings, [other])
    assert list(whole["networks"]) == ["ds", "pavement"] and whole["complete"] is True
    assert json.loads((tmp_path / "o" / "sim2real.json").read_text()) == whole


def striped_crack(i: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """A 40x32 noisy grey image with a dark 3 px band (the crack) at a row set by ``i``."""
    crack = np.zeros((32, 40), bool)
    crack[4 + 3 * i:7 + 3 * i, 3:36] = True
    rgb = rng.integers(90, 160, (32, 40, 3)).astype(np.uint8)
    rgb[crack] //= 3
    return rgb, crack


def test_repeats_report_the_network_of_median_f1_and_every_repeats_scores(tmp_path,
                                                                          monkeypatch, capsys):
    """--repeats 3: each training set trains three networks from their own draws; the scores
    given are those of the median F1, with the range and every repeat's scores beside them,
    and the first repeat is the run of --repeats 1."""
    from glsynth.model import sim2real

    rng = make_rng(3, 0, Stream.TRAINING)
    rendered = [CrackImage(f"v{i}", *striped_crack(i, rng)) for i in range(3)]
    monkeypatch.setattr(sim2real, "read_synthetic", lambda path: rendered)
    real = tmp_path / "photos"
    (real / "images").mkdir(parents=True)
    (real / "masks").mkdir()
    for i in range(3, 6):
        rgb, crack = striped_crack(i, rng)
        cv2.imwrite(str(real / "images" / f"p{i}.png"), rgb)
        cv2.imwrite(str(real / "masks" / f"p{i}.png"), crack.astype(np.uint8) * 255)
    settings = sim2real.Sim2RealSettings(steps=12, crop=16, batch=2, width=4, learning_rate=1e-2,
                                         test_share=1.0, repeats=1)
    once = sim2real.run_sim2real([tmp_path / "ds"], real, tmp_path / "one", settings)
    thrice = sim2real.run_sim2real([tmp_path / "ds"], real, tmp_path / "three",
                                   dataclasses.replace(settings, repeats=3))
    net = thrice["networks"]["ds"]
    f1s = [r["f1"] for r in net["repeats"]]
    assert len(set(f1s)) == 3  # each from its own draws, so the median is a choice
    assert net["f1"] == sorted(f1s)[1] and net["f1"] != f1s[0]
    median = net["repeats"][net["median_repeat"]]
    assert {k: net[k] for k in median} == median  # every figure the median run's
    assert net["f1_range"] == [min(f1s), max(f1s)]
    first, alone = net["repeats"][0], once["networks"]["ds"]
    assert {k: first[k] for k in first if k != "train_s"} == \
        {k: alone[k] for k in first if k != "train_s"}  # repeat 0 is the run without repeats
    assert set(alone) == set(first) | {"trained_on"}
    assert sim2real.repeat_item(2) != sim2real.SPLIT_ITEM
    assert "the median of 3 repeats" in sim2real.summary(thrice)
    assert main(["bench", "sim2real", "--synthetic", str(tmp_path / "ds"), "--real", str(real),
                 "--out", str(tmp_path / "o"), "--repeats", "101"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--repeats 101: must be an integer in [1, 100]" in err and "\n" not in err


def banded_real(root: Path, visible: dict[str, bool]) -> Path:
    """A real folder whose image k has its crack at rows of its own (so masks cannot stand in
    for each other); the crack is dark in the image where ``visible`` says so, else absent."""
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    for k, (name, seen) in enumerate(visible.items()):
        image = np.full((32, 40, 3), 120, np.uint8)
        mask = np.zeros((32, 40), np.uint8)
        rows = slice(2 + 6 * k, 5 + 6 * k)
        mask[rows, 3:30] = 255
        if seen:
            image[rows, 3:30] = 10
        cv2.imwrite(str(root / "images" / f"{name}.png"), image)
        cv2.imwrite(str(root / "masks" / f"{name}.png"), mask)
    return root


def test_groups_are_scored_each_at_its_own_threshold(tmp_path, monkeypatch, capsys):
    """--groups: every network is also scored on each group of the real folder alone. The
    network is replaced by one that finds exactly the dark pixels, so a group of photographs
    whose cracks are dark scores 1, one whose crack is invisible 0, one of each finds half
    its crack, and a group of every image the network's whole score; with a split, a group
    of each held-out image scores that image alone."""
    from glsynth.model import sim2real

    visible = {"p3": True, "p4": True, "p5": False, "p6": True}
    real = banded_real(tmp_path / "photos", visible)
    rendered = [CrackImage("v", *striped_crack(0, make_rng(3, 0, Stream.TRAINING)))]
    monkeypatch.setattr(sim2real, "read_synthetic", lambda path: rendered)
    monkeypatch.setattr(sim2real, "predict", lambda net, rgb, device=None:
                        (rgb.mean(axis=2) < 60).astype(np.float32))
    groups = tmp_path / "groups.json"
    groups.write_text(json.dumps({"seen": ["p3", "p4.PNG"], "unseen": ["p5"],
                                  "half": ["p5", "p6", "p6"], "every": list(visible)}))
    argv = ["bench", "sim2real", "--synthetic", str(tmp_path / "ds"), "--real", str(real),
            "--groups", str(groups), "--steps", "1", "--crop", "16", "--batch", "1",
            "--width", "4"]
    assert main(argv + ["--test-share", "1", "--out", str(tmp_path / "o"),
                        "--repeats", "2"]) == 0
    result = json.loads((tmp_path / "o" / "sim2real.json").read_text())
    assert result["groups"] == {"seen": 2, "unseen": 1, "half": 2, "every": 4}
    net = result["networks"]["ds"]
    for run in (net, *net["repeats"]):
        by_group = run["groups"]
        assert by_group["seen"]["f1"] == 1.0 and by_group["unseen"]["f1"] == 0.0
        assert by_group["half"]["precision"] == 1.0 and by_group["half"]["recall"] == 0.5
        assert by_group["every"] == {k: run[k] for k in by_group["every"]}
        assert run["recall"] == 0.75
    assert "by group: seen F1 1.000 (P 1.000, R 1.000), unseen F1 0.000" in \
        capsys.readouterr().out

    settings = sim2real.Sim2RealSettings(test_share=0.5)
    _, test = sim2real.split_real(read_real_folder(real), settings)
    held = [image.name for image in test if visible[image.name]]
    groups.write_text(json.dumps({name: [name] for name in held}))
    assert main(argv + ["--test-share", "0.5", "--out", str(tmp_path / "split"),
                        "--repeats", "1"]) == 0
    split = json.loads((tmp_path / "split" / "sim2real.json").read_text())
    assert split["test_images"] == 2 and list(split["groups"]) == held
    assert all(g["f1"] == 1.0 for g in split["networks"]["ds"]["groups"].values())


def test_group_names_are_file_names_with_or_without_their_suffix(tmp_path):
    from glsynth.data.crack_folders import group_members, read_groups

    images = [CrackImage(name, np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), bool))
              for name in ("a", "IMG_1.2", "scan.png")]
    groups = {"g": ["a.JPG", "IMG_1.2", "IMG_1.2.jpg", "scan.png", "scan.png.tif", "a"]}
    assert group_members(groups, images) == {"g": [0, 1, 2]}
    with pytest.raises(UserError, match="group 'g' names 'a.gif', not an image of the --real "
                                        "folder \\(1 such\\)"):
        group_members({"g": ["a", "a.gif"]}, images)
    path = tmp_path / "g.json"
    path.write_text(json.dumps(groups))
    assert read_groups(path) == groups


@pytest.mark.parametrize("content, words", [
    (None, "--groups file '{path}' does not exist"),
    ("{not json", "is not valid JSON"),
    ("[]", "is not a non-empty JSON object"),
    ("{}", "is not a non-empty JSON object"),
    ('{"a": []}', "group 'a' is not a non-empty list of image names"),
    ('{"a": ["a", 3]}', "group 'a' is not a non-empty list of image names"),
    ('{"a": ["images/a.jpg"]}', "group 'a' names 'images/a.jpg', a path"),
    ('{"a": ["a", "c.jpg", "d"]}', "group 'a' names 'c.jpg', not an image of the --real folder "
                                   "(2 such)"),
    ('{"a": ["a"], "b": ["b"]}', "group '{held}' has no image among the 1 held out"),
    ('{"a": ["a"], "b": ["b"]}', "group 'b' has no crack pixel in its held-out masks"),
])
def test_bad_groups_are_refused_in_one_line_before_training(tmp_path, capsys, content, words):
    """Each refused before any glsynth dataset is read (the one given does not exist) and
    before the output folder is made; a file that cannot be a groups file, before the real
    folder is read too (its images here are unreadable)."""
    from glsynth.model.sim2real import Sim2RealSettings, split_real

    real, path = write_real(tmp_path / "photos"), tmp_path / "groups.json"
    if content is not None:
        path.write_text(content)
    share = "0.5" if "held out" in words else "1"
    _, test = split_real(read_real_folder(real), Sim2RealSettings(test_share=0.5))
    held = ({"a", "b"} - {test[0].name}).pop()  # the group whose one image trains
    if "crack pixel" in words:
        cv2.imwrite(str(real / "masks" / "b.png"), np.zeros((32, 40), np.uint8))
    if "names" not in words and "held" not in words and "crack" not in words:
        (real / "images" / "a.jpg").write_bytes(b"not a jpeg")
    assert main(["bench", "sim2real", "--synthetic", str(tmp_path / "ds"), "--real", str(real),
                 "--groups", str(path), "--test-share", share,
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert words.format(path=path, held=held) in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_many_networks_bench_summarises_and_refuses_a_bad_folder_in_one_line(tmp_path):
    """bench_sim2real_many: medians, means and spreads per step count and training set; a
    folder that cannot be read is refused in one line before any worker starts (a worker
    pool would restart a failing worker forever)."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parent.parent
    sys.path.insert(0, str(root / "bench"))
    import bench_sim2real_many

    networks = [{"trained_on": name, "steps": steps, "f1": f1}
                for name, steps, f1 in (("ds", 300, 0.5), ("ds", 300, 0.7), ("ds", 300, 0.6),
                                        ("pave", 300, 0.4), ("ds", 1500, 0.8))]
    summary = bench_sim2real_many.summarise(networks)
    assert summary["300"]["ds"] == {"networks": 3, "median": 0.6, "mean": pytest.approx(0.6),
                                    "sd": pytest.approx(0.1), "range": [0.5, 0.7]}
    assert summary["300"]["pave"]["median"] == 0.4 and list(summary["1500"]) == ["ds"]
    done = subprocess.run([sys.executable, str(root / "bench" / "bench_sim2real_many.py"),
                           "--real", str(tmp_path / "none"), "--synthetic", str(tmp_path),
                           "--device", "cpu", "--name", "never"],
                          capture_output=True, text=True, timeout=120)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(lines) == 1 and "bench_sim2real_many:" in lines[0]
    # Two sets of one folder name, and a plan that is no steps:repeats list: one line each.
    for extra, words in ((["--other-real", str(tmp_path / "a" / "x"), str(tmp_path / "b" / "x")],
                          "different folder names"), (["--plan", "300"], "--plan '300'")):
        done = subprocess.run([sys.executable, str(root / "bench" / "bench_sim2real_many.py"),
                               "--real", str(tmp_path / "none"), "--synthetic", str(tmp_path),
                               "--device", "cpu", "--name", "never", *extra],
                              capture_output=True, text=True, timeout=120)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 1 and len(lines) == 1 and words in lines[0]
    assert not (root / "bench" / "results" / "never.json").exists()
