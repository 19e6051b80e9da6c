"""FCN58, losses, metrics, training, evaluation and prediction (paper Sections 4.1-4.6)."""

import json
import math

import numpy as np
import pytest
import torch
from conftest import TINY_TRAINING
from glsynth.model.fcn58 import FCN58, count_macs, parameter_count
from glsynth.model.losses import berhu, class_frequencies, mfb_weights, weighted_cross_entropy
from glsynth.model.metrics import confusion, depth_errors, pooled_depth, segmentation_scores
from glsynth.model.runtime import predict_ids
from glsynth.model.train import flip_batch, seeded_torch, torch_generator

from glsynth.cli import main


# --- network ---------------------------------------------------------------------------------
def test_parameter_counts_match_the_independent_reading_of_table_6():
    assert [parameter_count(FCN58(c)) for c in (8, 3, 1)] == [940_608, 937_938, 936_870]


def test_macs_at_full_size():
    # 9.55 G: an independent count of the same reading of Table 6 (docs/design.md).
    assert abs(count_macs(FCN58(8), 1080, 1920) / 9.55e9 - 1) < 1e-3


@pytest.mark.parametrize("height, width", [(1080, 1920), (97, 131), (360, 640), (96, 96)])
def test_output_is_a_third_rounded_up(height, width):
    model = FCN58(3).eval()
    with torch.no_grad():
        out = model(torch.rand(1, 3, height, width))
    assert out.shape == (1, 3, math.ceil(height / 3), math.ceil(width / 3))
    assert torch.isfinite(out).all()


def test_bad_inputs_say_how_to_fix():
    with pytest.raises(ValueError, match="at least 96 px"):
        FCN58(3)(torch.rand(1, 3, 64, 200))
    with pytest.raises(ValueError, match=r"\(N, 3, H, W\)"):
        FCN58(3)(torch.rand(3, 100, 100))


# --- losses ----------------------------------------------------------------------------------
def test_weighted_cross_entropy_by_hand():
    logits = torch.tensor([[0.0, 2.0], [1.0, 0.0], [5.0, -5.0]]).T.reshape(1, 2, 1, 3)
    labels = torch.tensor([[[2, 1, 0]]])  # the third pixel is ignored
    weights = torch.tensor([0.5, 2.0])
    ce = [math.log1p(math.exp(-2.0)), math.log1p(math.exp(-1.0))]  # -log softmax
    expected = (2.0 * ce[0] + 0.5 * ce[1]) / 2.5
    assert float(weighted_cross_entropy(logits, labels, weights)) == pytest.approx(expected)


def test_cross_entropy_with_all_pixels_ignored_or_weightless_is_zero_with_finite_gradients():
    logits = torch.randn(2, 3, 4, 5, requires_grad=True)
    for labels, weights in ((torch.zeros(2, 4, 5, dtype=torch.long), torch.ones(3)),
                            (torch.full((2, 4, 5), 3), torch.tensor([1.0, 1.0, 0.0]))):
        loss = weighted_cross_entropy(logits, labels, weights)
        loss.backward()
        assert loss.item() == 0.0 and torch.isfinite(logits.grad).all()
        logits.grad = None


def test_cross_entropy_size_mismatch_is_a_clear_error():
    with pytest.raises(ValueError, match="ceil"):
        weighted_cross_entropy(torch.zeros(1, 3, 4, 4), torch.ones(1, 5, 5), torch.ones(3))


def test_berhu_by_hand():
    prediction = torch.tensor([1.1, 3.0, 5.0])
    target = torch.tensor([1.0, 2.0, 5.0])
    c = 0.2 * 1.0  # 0.2 max|e|
    expected = (0.1 + (1.0 + c * c) / (2 * c) + 0.0) / 3
    assert float(berhu(prediction, target)) == pytest.approx(expected, rel=1e-6)


def test_berhu_with_zero_error_has_finite_gradients():
    prediction = torch.full((2, 5, 7), 4.0, requires_grad=True)
    loss = berhu(prediction, torch.full((2, 5, 7), 4.0))
    loss.backward()
    assert loss.item() == 0.0
    assert torch.isfinite(prediction.grad).all() and float(prediction.grad.abs().max()) == 0.0
    empty = berhu(prediction, prediction.detach(), valid=torch.zeros(2, 5, 7, dtype=torch.bool))
    assert empty.item() == 0.0


def test_median_frequency_weights_with_an_absent_class():
    freq = class_frequencies([50, 25, 0], [100, 100, 0])
    assert freq[:2].tolist() == [0.5, 0.25] and math.isnan(freq[2])
    assert mfb_weights(freq).tolist() == [0.75, 1.5, 0.0]
    assert mfb_weights(class_frequencies([0, 0], [0, 0])).tolist() == [0.0, 0.0]


def test_component_prediction_divides_by_the_weights_and_never_picks_absent_classes():
    logits = torch.log(torch.tensor([0.5, 0.3, 0.2])).view(1, 3, 1, 1)
    assert predict_ids("damage", logits, None).item() == 1
    assert predict_ids("component", logits, torch.tensor([1.0, 0.5, 1.0])).item() == 2
    assert predict_ids("component", logits, torch.tensor([0.0, 0.0, 1.0])).item() == 3


def test_flips_move_image_and_target_together():
    images = torch.arange(2 * 3 * 2 * 4, dtype=torch.float32).view(2, 3, 2, 4)
    targets = torch.arange(2 * 2 * 4).view(2, 2, 4)
    flipped, moved = flip_batch(images, targets, torch_generator(3))
    for i in range(2):
        same = torch.equal(flipped[i], images[i])
        assert same or torch.equal(flipped[i], images[i].flip(-1))
        assert torch.equal(moved[i], targets[i] if same else targets[i].flip(-1))


# --- metrics ---------------------------------------------------------------------------------
def test_confusion_and_scores_by_hand():
    truth = np.array([1, 1, 2, 2, 0, 3])
    predicted = np.array([1, 2, 2, 2, 3, 1])
    m = confusion(truth, predicted, 3)
    assert m.tolist() == [[1, 1, 0], [0, 2, 0], [1, 0, 0]]
    s = segmentation_scores(m, ["a", "b", "c"])["per_class"]
    assert s["a"] == {"precision": 0.5, "recall": 0.5, "iou": 1 / 3, "pixels": 2}
    assert s["b"]["precision"] == pytest.approx(2 / 3) and s["b"]["recall"] == 1.0
    assert s["c"] == {"precision": 0.0, "recall": 0.0, "iou": 0.0, "pixels": 1}


def test_absent_class_has_no_score_and_stays_out_of_the_means():
    m = confusion(np.array([1, 2]), np.array([1, 2]), 3)
    scores = segmentation_scores(m, ["a", "b", "c"])
    assert scores["per_class"]["c"]["iou"] is None
    assert scores["mean"] == {"precision": 1.0, "recall": 1.0, "iou": 1.0}
    empty = segmentation_scores(confusion(np.zeros(4, int), np.ones(4, int), 3), ["a", "b", "c"])
    assert empty["mean"]["iou"] is None


def test_depth_errors_by_hand_within_the_range():
    # 30 m and 0.5 m are the code's clips (sky, too near); 0.2 m lies below the range.
    truth = np.array([1.0, 2.0, 4.0, 30.0, 0.2, 0.5])
    predicted = np.array([1.5, 2.0, 3.0, 10.0, 5.0, 3.0])
    d = pooled_depth([depth_errors(predicted, truth)])
    assert d["pixels"] == 3
    assert d["mae_m"] == pytest.approx(0.5) and d["rmse_m"] == pytest.approx(math.sqrt(1.25 / 3))
    assert d["ard"] == pytest.approx((0.5 + 0.0 + 0.25) / 3)
    assert pooled_depth([depth_errors(predicted[3:], truth[3:])])["mae_m"] is None


# --- training --------------------------------------------------------------------------------
@pytest.mark.slow  # trains
def test_overfitting_one_tiny_batch_drives_the_loss_down():
    with seeded_torch(0):
        model = FCN58(3)
        images = torch.rand(2, 3, 96, 96)
    labels = torch.ones(2, 32, 32, dtype=torch.long)
    labels[:, :, 16:] = 2
    labels[0, :8] = 3
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(30):  # the ratio is 0.044 after 30 steps, 0.022 after 40
        loss = weighted_cross_entropy(model(images), labels, torch.ones(3))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < 0.2 * losses[0]


# --- on generated data -----------------------------------------------------------------------
SMALL_TRAINING = TINY_TRAINING["component"]


@pytest.fixture(scope="module")
def component_run(tiny_run):
    return tiny_run("component")


def test_training_run_writes_its_files(component_run):
    for name in ("settings.json", "class_weights.json", "checkpoint.pt", "history.json",
                 "curves.png", "model.pt"):
        assert (component_run / name).is_file(), name
    history = json.loads((component_run / "history.json").read_text())
    assert [h["epoch"] for h in history] == [1, 2]
    assert all(math.isfinite(h["train_loss"]) for h in history)
    weights = json.loads((component_run / "class_weights.json").read_text())["weights"]
    assert weights[7] > 0.0  # "other" (class 8) occurs: the demo preset draws the others
    checkpoint = torch.load(component_run / "checkpoint.pt", weights_only=True)
    assert checkpoint["epoch"] == 2


def test_resumed_training_equals_an_uninterrupted_run(tiny_dataset, component_run, tmp_path):
    from glsynth.model.runtime import load_torch
    from glsynth.model.settings import settings_from_json
    from glsynth.model.train import train

    settings = settings_from_json(json.loads((component_run / "settings.json").read_text()))

    def stop_after_first_epoch(line: str) -> None:
        raise KeyboardInterrupt(line)

    run = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train(settings, run, log=stop_after_first_epoch)
    assert load_torch(run / "checkpoint.pt")["epoch"] == 1 and not (run / "model.pt").exists()
    train(settings, run, log=lambda line: None)
    resumed = load_torch(run / "model.pt")["state_dict"]
    reference = load_torch(component_run / "model.pt")["state_dict"]
    for name, tensor in reference.items():
        assert torch.equal(tensor, resumed[name]), name


def test_a_run_folder_with_other_settings_is_refused(tiny_dataset, component_run, capsys):
    assert main(["train", "--task", "component", "--data", str(tiny_dataset), "--out",
                 str(component_run), *SMALL_TRAINING[:-1], "2"]) == 2
    assert "other settings" in capsys.readouterr().err


def test_evaluate_and_predict_on_generated_data(tiny_dataset, component_run, tmp_path):
    from PIL import Image

    from glsynth.core.images import nearest_resize
    from glsynth.data.tokaido import read_manifest

    assert main(["evaluate", "--run", str(component_run), "--data", str(tiny_dataset),
                 "--examples", "1"]) == 0
    out = component_run / "eval_test"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["images"] == sum(r.regular for r in read_manifest(tiny_dataset,
                                                                      "files_test.csv"))
    # Every labelled pixel of the test targets (read from the BMPs, at the 64x36 output size)
    # is counted once.
    labelled = 0
    for row in read_manifest(tiny_dataset, "files_test.csv"):
        if row.regular:
            ids = nearest_resize(np.asarray(Image.open(tiny_dataset / row.component)), (36, 64))
            labelled += int((ids > 0).sum())
    assert np.asarray(metrics["confusion"]).sum() == labelled > 0
    assert (out / "confusion.png").is_file() and (out / "examples" / "example_0.png").is_file()
    image = tiny_dataset / read_manifest(tiny_dataset, "files_test.csv")[0].image
    assert main(["predict", "--run", str(component_run), str(image), "--out",
                 str(tmp_path)]) == 0
    ids = np.asarray(Image.open(tmp_path / f"{image.stem}_component.png"))
    assert ids.shape == (36, 64) and set(np.unique(ids)) <= set(range(1, 8))
    assert Image.open(tmp_path / f"{image.stem}_component_overlay.png").size == (1920, 1080)


@pytest.mark.parametrize("task", ["damage", "depth"])
def test_damage_and_depth_train_and_evaluate(tiny_dataset, tiny_run, task):
    run = tiny_run(task)  # trained as --batch-size 4 --schedule 1e-3:1 --precision fp32
    assert (run / "model.pt").is_file()
    assert main(["evaluate", "--run", str(run), "--data", str(tiny_dataset),
                 "--examples", "0"]) == 0
    metrics = json.loads((run / "eval_test" / "metrics.json").read_text())
    if task == "depth":
        assert metrics["depth"]["pixels"] > 0 and math.isfinite(metrics["depth"]["mae_m"])
    else:
        assert metrics["per_image"] and all(
            0.0 <= r["damage_pixel_ratio"] <= 1.0 for r in metrics["per_image"])


def test_extra_real_folders_are_mixed_in(tiny_dataset, tmp_path):
    from glsynth.model.data import ImageFolder
    from PIL import Image

    real = tmp_path / "real"
    (real / "images").mkdir(parents=True)
    (real / "labels").mkdir()
    Image.new("RGB", (300, 200), (120, 120, 120)).save(real / "images" / "a.jpg")
    Image.fromarray(np.full((200, 300), 4, np.uint8)).save(real / "labels" / "a.png")
    folder = ImageFolder(real, "component", (192, 108))
    image, target = folder[0]
    assert image.shape == (3, 108, 192) and target.shape == (36, 64)
    assert set(target.unique().tolist()) == {4}
    run = tmp_path / "run"
    assert main(["train", "--task", "component", "--data", str(tiny_dataset), "--out",
                 str(run), "--extra", str(real), "--image-size", "192x108", "--schedule",
                 "1e-3:1", "--loader-workers", "0"]) == 0
    (real / "labels" / "a.png").unlink()
    with pytest.raises(ValueError, match="no label map"):
        ImageFolder(real, "component")


def test_missing_run_is_a_clear_error(tmp_path, capsys):
    assert main(["predict", "--run", str(tmp_path / "nope"), "x.png", "--out",
                 str(tmp_path)]) == 2
    assert "has no model.pt" in capsys.readouterr().err


def test_torchrun_two_processes_train_with_distributed_data_parallel(tiny_dataset, tmp_path):
    import os
    import subprocess
    import sys

    run = tmp_path / "ddp"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone",
                    "--nproc_per_node", "2", "-m", "glsynth", "train", "--task", "depth",
                    "--data", str(tiny_dataset), "--out", str(run), "--image-size", "192x108",
                    "--batch-size", "2", "--schedule", "1e-3:1", "--loader-workers", "0"],
                   check=True, env=env, capture_output=True, timeout=300)
    history = json.loads((run / "history.json").read_text())
    assert len(history) == 1 and math.isfinite(history[0]["train_loss"])
    assert (run / "model.pt").is_file()


def test_depth_training_ignores_the_clipped_pixels_evaluation_ignores():
    """Sky (30 m) and too-near (0.5 m) truths are clips: the loss does not see them, as the
    metrics do not."""
    from glsynth.model.metrics import depth_valid
    from glsynth.model.train import task_loss

    truth = torch.tensor([[[2.0, 30.0], [0.5, 7.0]]])
    output = torch.tensor([[[[2.5, 1.0], [9.0, 6.0]]]])
    moved = output.clone()
    moved[0, 0, 0, 1] = 50.0  # predictions at clipped pixels change nothing
    moved[0, 0, 1, 0] = -3.0
    assert task_loss("depth", output, truth, None) == task_loss("depth", moved, truth, None)
    assert depth_valid(truth).tolist() == [[[True, False], [False, True]]]
    assert depth_valid(truth.numpy()).tolist() == depth_valid(truth).tolist()
