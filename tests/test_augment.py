"""Photometric augmentation (glsynth.model.augment) and the cache of resized training inputs
(glsynth.model.data.InputCache), on rendered images of the tiny dataset."""

import json
import os
import shutil

import cv2
import numpy as np
import pytest
import torch
from glsynth.model import augment as aug
from glsynth.model.data import InputCache, TokaidoDataset, load_image
from glsynth.model.settings import AUGMENTATIONS, parse_augment

from glsynth.cli import main
from glsynth.core.errors import UserError
from glsynth.data.tokaido import read_manifest


@pytest.fixture(scope="module")
def rendered(tiny_dataset) -> torch.Tensor:
    """Three rendered views at 480x270, (3, 3, 270, 480) in [0, 1]."""
    rows = read_manifest(tiny_dataset, "files_train.csv")[:3]
    return torch.stack([load_image(tiny_dataset / r.image, (480, 270)) for r in rows])


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(255.0 ** 2 / np.mean((a.astype(float) - b) ** 2)))


def only(names: tuple[str, ...], images: torch.Tensor, seed: int = 0) -> torch.Tensor:
    return aug.photometric(images, names, torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("quality", [30, 60, 95])
def test_jpeg_round_trip_is_libjpeg_within_its_own_error(rendered, quality):
    ours = aug.jpeg(rendered, torch.full((3,), float(quality)))
    for image, mine in zip(rendered, ours):
        u8 = (image.permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
        _, code = cv2.imencode(".jpg", cv2.cvtColor(u8, cv2.COLOR_RGB2BGR),
                               [cv2.IMWRITE_JPEG_QUALITY, quality])
        libjpeg = cv2.cvtColor(cv2.imdecode(code, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        mine = mine.permute(1, 2, 0).numpy() * 255
        # Measured: 43-50 dB from libjpeg, and the same loss (within 0.4-1.8 dB) as libjpeg's.
        assert psnr(mine, libjpeg) > 40
        assert abs(psnr(mine, u8) - psnr(libjpeg, u8)) < 2.5
        assert psnr(mine, u8) < 55  # it did compress


def test_quantisation_tables_follow_the_ijg_scale():
    tables = aug.quant_tables(torch.tensor([50.0, 100.0, 1.0]))
    assert tables[0, 0, 0, 0] == 16 and tables[0, 1, 0, 0] == 17  # quality 50: the tables
    assert (tables[1] == 1).all()  # quality 100: no quantisation
    assert (tables[2] == 255).all()  # quality 1: the coarsest


def test_blur_keeps_constants_and_spreads_an_impulse_by_sigma():
    flat = torch.full((2, 3, 40, 40), 0.3)
    assert torch.allclose(aug.gaussian_blur(flat, torch.tensor([0.0, 1.5])), flat, atol=1e-6)
    impulse = torch.zeros(2, 3, 41, 41)
    impulse[:, :, 20, 20] = 1.0
    out = aug.gaussian_blur(impulse, torch.tensor([0.0, 1.2]))
    assert torch.allclose(out[0], impulse[0], atol=1e-6)  # sigma 0: unchanged
    profile = out[1, 0].sum(0)
    x = torch.arange(41.0) - 20
    assert float(profile.sum()) == pytest.approx(1.0, abs=1e-5)
    assert float((profile * x ** 2).sum()) == pytest.approx(1.2 ** 2, rel=0.02)


def test_exposure_and_white_balance_scale_linear_light(rendered):
    lin = aug.srgb_to_linear(rendered)
    for seed in range(4):
        ratio = aug.srgb_to_linear(only(("exposure", "white_balance"), rendered, seed)) / \
            lin.clamp_min(1e-6)
        ok = (lin > 0.02) & (lin < 0.2)  # lit and never clipped by a 2.3x gain
        for b in range(3):
            gains = [float(ratio[b, c][ok[b, c]].median()) for c in range(3)]
            for c in range(3):
                spread = ratio[b, c][ok[b, c]]
                assert float((spread - gains[c]).abs().max()) < 2e-3  # one gain per channel
            assert 0.5 - 1e-3 <= gains[1] <= 2.0 + 1e-3
            for c in (0, 2):
                assert 1 - aug.WHITE_BALANCE - 1e-3 <= gains[c] / gains[1] <= \
                    1 + aug.WHITE_BALANCE + 1e-3


def test_noise_follows_the_sensor_model_and_extremes_stay_in_range():
    grey = torch.full((64, 3, 32, 32), 0.5)
    noisy = aug.srgb_to_linear(only(("noise",), grey))
    x = float(aug.srgb_to_linear(torch.tensor(0.5)))
    std = (noisy - x).flatten(1).std(1)
    bound = (aug.NOISE_SHOT[1] * x + aug.NOISE_READ[1] ** 2) ** 0.5
    assert (std <= bound * 1.1).all()
    assert (std < 1e-6).sum() > 10 and (std > bound * 0.2).sum() > 10  # half of them untouched
    for value in (0.0, 1.0):  # black and white frames: finite and in [0, 1]
        out = only(AUGMENTATIONS, torch.full((8, 3, 20, 36), value))
        assert torch.isfinite(out).all() and out.min() >= 0 and out.max() <= 1


def test_augmentation_is_reproducible_from_its_seed(rendered):
    a = only(AUGMENTATIONS, rendered, 3)
    assert torch.equal(a, only(AUGMENTATIONS, rendered, 3))
    assert not torch.equal(a, only(AUGMENTATIONS, rendered, 4))
    assert a.shape == rendered.shape and a.dtype == torch.float32


def test_augment_option_parsing():
    assert parse_augment("all") == AUGMENTATIONS
    assert parse_augment("none") == ()
    assert parse_augment("jpeg, blur") == ("blur", "jpeg")
    with pytest.raises(UserError, match="unknown sepia"):
        parse_augment("blur,sepia")


def test_input_cache_gives_the_same_tensors_and_decodes_each_image_once(tiny_dataset, tmp_path,
                                                                        monkeypatch):
    import glsynth.model.data as data

    plain = TokaidoDataset(tiny_dataset, "train", image_size=(480, 270))
    cached = TokaidoDataset(tiny_dataset, "train", image_size=(480, 270), cache=True)
    first = [cached.image(i) for i in range(len(cached))]
    for i, tensor in enumerate(first):
        assert torch.equal(tensor, plain.image(i))
    assert len(list(cached.cache.dir.glob("*/*.npz"))) == len(cached)

    def no_decoding(path):
        raise AssertionError(f"decoded {path} again")

    monkeypatch.setattr(data, "read_rgb", no_decoding)
    for i, tensor in enumerate(first):
        assert torch.equal(cached.image(i), tensor)
    other_size = InputCache(tiny_dataset, (192, 108))
    assert other_size.dir != cached.cache.dir


def test_input_cache_decodes_a_changed_image_again(tiny_dataset, tmp_path):
    row = read_manifest(tiny_dataset, "files_train.csv")[0]
    image = tmp_path / "view.png"
    shutil.copy(tiny_dataset / row.image, image)
    cache = InputCache(tmp_path, (96, 54), base=tmp_path / "cache")
    before = cache.load(image)
    flipped = cv2.imread(str(image))[:, ::-1]
    cv2.imwrite(str(image), flipped)
    os.utime(image, ns=(1, 1))
    after = cache.load(image)
    assert torch.equal(after, load_image(image, (96, 54))) and not torch.equal(after, before)
    assert len(list(cache.dir.glob("*/*.npz"))) == 1  # the stale entry is gone


def test_augmented_cached_training_is_reproducible(tiny_dataset, tmp_path):
    from glsynth.model.runtime import load_torch

    options = ["--task", "component", "--data", str(tiny_dataset), "--image-size", "192x108",
               "--batch-size", "2", "--schedule", "1e-3:1", "--loader-workers", "0",
               "--augment", "all", "--cache-inputs"]
    weights = []
    for name in ("a", "b"):
        assert main(["train", *options, "--out", str(tmp_path / name)]) == 0
        weights.append(load_torch(tmp_path / name / "model.pt")["state_dict"])
    assert json.loads((tmp_path / "a" / "settings.json").read_text())["augment"] == \
        list(AUGMENTATIONS)
    for name, tensor in weights[0].items():
        assert torch.equal(tensor, weights[1][name]), name


def test_a_bad_augment_option_is_refused_before_any_work(tiny_dataset, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:  # argparse: one error line
        main(["train", "--task", "component", "--data", str(tiny_dataset), "--out",
              str(tmp_path / "r"), "--augment", "vignette"])
    assert stop.value.code == 2 and not (tmp_path / "r").exists()
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--augment" in line and "vignette" in line and "give all, none" in line
