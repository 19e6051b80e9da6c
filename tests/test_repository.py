import numpy as np
import pytest
from PIL import Image

from glsynth.appearance.repository import TextureRepository, generate_repository
from glsynth.appearance.texgen import CATEGORIES


@pytest.fixture()
def repo_dir(tmp_path):
    return generate_repository(tmp_path / "repo", seed=3, per_category=2, size=32)


def test_generated_repository_has_every_category_and_is_deterministic(repo_dir, tmp_path):
    again = generate_repository(tmp_path / "again", seed=3, per_category=2, size=32)
    for category in CATEGORIES:
        files = sorted((repo_dir / category).glob("*.png"))
        assert len(files) == 2
        for f in files:
            assert f.read_bytes() == (again / category / f.name).read_bytes()
    other = generate_repository(tmp_path / "other", seed=4, per_category=1, size=32)
    assert (other / "concrete" / "concrete_0000.png").read_bytes() != \
        (repo_dir / "concrete" / "concrete_0000.png").read_bytes()


def test_images_are_resized_rgb_and_shared(repo_dir):
    repo = TextureRepository(repo_dir, 16)
    image = repo.image("wood", 1)
    assert image.shape == (16, 16, 3) and image.dtype == np.uint8
    assert repo.image("wood", 1) is image  # loaded once, then shared
    assert repo.image("wood", 3) is image  # indices wrap


def test_unreadable_image_is_skipped_with_a_warning_naming_it(repo_dir):
    bad = repo_dir / "steel" / "steel_0000.png"
    bad.write_bytes(b"not a png")
    repo = TextureRepository(repo_dir, 16)
    with pytest.warns(UserWarning, match="steel_0000.png"):
        image = repo.image("steel", 0)
    good = np.asarray(Image.open(repo_dir / "steel" / "steel_0001.png").convert("RGB")
                      .resize((16, 16), Image.Resampling.LANCZOS))
    assert np.array_equal(image, good)


def test_category_with_no_readable_image_is_a_clear_error(repo_dir):
    for f in (repo_dir / "ground").glob("*.png"):
        f.write_bytes(b"broken")
    repo = TextureRepository(repo_dir, 16)
    with pytest.warns(UserWarning), pytest.raises(ValueError, match="no readable image in "
                                                                     "category 'ground'"):
        repo.image("ground", 0)


def test_missing_category_or_folder_says_how_to_fix(repo_dir, tmp_path):
    for f in (repo_dir / "scene").glob("*"):
        f.unlink()
    with pytest.raises(ValueError, match="category folder 'scene' is missing.*glsynth textures"):
        TextureRepository(repo_dir, 16)
    with pytest.raises(ValueError, match="is not a folder"):
        TextureRepository(tmp_path / "nowhere", 16)


def test_user_photos_in_other_formats_are_found(repo_dir):
    Image.new("RGB", (40, 20), (200, 10, 10)).save(repo_dir / "painted" / "photo.JPG",
                                                   format="JPEG")
    repo = TextureRepository(repo_dir, 8)
    assert repo.count("painted") == 3
    names = [p.name for p in repo.files["painted"]]
    red = repo.image("painted", names.index("photo.JPG"))
    assert red[..., 0].mean() > 150 and red[..., 1].mean() < 60


def test_builtin_repository_has_the_same_images_at_every_texture_size():
    """Quality presets change texture resolution only: the built-in repository is generated
    at builtin_size, and every texture_size is resized from those images."""
    from glsynth.appearance.dressing import open_repository
    from glsynth.core.config import Config, MaterialsConfig

    def repo(size: int) -> TextureRepository:
        return open_repository(Config(materials=MaterialsConfig(
            texture_size=size, builtin_size=64, images_per_category=1)))

    small, large = repo(16), repo(32)
    assert small.root == large.root
    for category in CATEGORIES:
        shrunk = np.asarray(Image.fromarray(large.image(category, 0)).resize(
            (16, 16), Image.Resampling.BOX), dtype=float)
        assert np.abs(shrunk - small.image(category, 0)).mean() < 4.0  # levels


def test_decoded_images_are_cached_by_content(repo_dir, monkeypatch, tmp_path):
    """A second repository reads the decoded image without decoding it; an edited image, or a
    damaged cache entry, is decoded again."""
    import glsynth.appearance.repository as repository

    monkeypatch.setenv("GLSYNTH_CACHE", str(tmp_path / "cache"))  # its entries are damaged

    first = TextureRepository(repo_dir, 16).image("concrete", 0)
    entries = sorted((repository.cache_root() / "decoded").glob("*.npy"))
    assert entries and any(np.array_equal(np.load(e), first) for e in entries)

    def no_decoding(*args, **kwargs):
        raise AssertionError("decoded again")

    with monkeypatch.context() as m:
        m.setattr(repository.Image, "open", no_decoding)
        assert np.array_equal(TextureRepository(repo_dir, 16).image("concrete", 0), first)

    path = repo_dir / "concrete" / "concrete_0000.png"
    Image.new("RGB", (32, 32), (250, 0, 0)).save(path)
    assert TextureRepository(repo_dir, 16).image("concrete", 0)[..., 0].min() == 250

    entries = set((repository.cache_root() / "decoded").glob("*.npy"))
    for entry in entries:
        entry.write_bytes(entry.read_bytes()[:100])  # truncated
    with pytest.warns(UserWarning, match="concrete_0000.png' again"):
        red = TextureRepository(repo_dir, 16).image("concrete", 0)
    assert red[..., 0].min() == 250

    def readable(entry):
        try:
            return np.array_equal(np.load(entry), red)
        except ValueError:
            return False

    assert any(readable(e) for e in entries)  # replaced


def _tree(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


def test_the_images_are_the_same_made_on_one_thread_or_several(tmp_path, monkeypatch):
    from glsynth.appearance import repository

    several = generate_repository(tmp_path / "several", seed=5, per_category=3, size=32)
    monkeypatch.setattr(repository, "BUILD_THREADS", 1)
    one = generate_repository(tmp_path / "one", seed=5, per_category=3, size=32)
    assert _tree(several) == _tree(one) and len(_tree(one)) == 3 * len(CATEGORIES)


def _build_builtin(cache: str) -> None:
    import os

    os.environ["GLSYNTH_CACHE"] = cache
    from glsynth.appearance.repository import builtin_repository

    builtin_repository(seed=6, per_category=4, size=64)


def _blocked_on_a_lock(pid: int, timeout_s: float = 60.0) -> bool:
    """Whether process ``pid`` comes to wait for a file lock within ``timeout_s``: Linux lists
    a blocked request in /proc/locks with "->" before it (a spawned child takes a second or
    more to import and reach the lock, so no fixed wait would be sure)."""
    import time

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        with open("/proc/locks") as locks:
            if any(line.split()[1] == "->" and f" {pid} " in line for line in locks):
                return True
        time.sleep(0.02)
    return False


def test_a_process_waits_for_the_one_making_the_builtin_repository(tmp_path, monkeypatch):
    """As a dataset's workers do on a fresh cache: while one process holds the repository's
    lock, another that asks for it waits, making nothing; once the lock is free it finds or
    makes every image, equal to one made alone, with no temporary file left."""
    import fcntl
    import multiprocessing

    from glsynth.appearance.repository import builtin_root

    monkeypatch.setenv("GLSYNTH_CACHE", str(tmp_path / "cache"))
    root = builtin_root(seed=6, per_category=4, size=64)
    root.mkdir(parents=True)
    child = multiprocessing.get_context("spawn").Process(target=_build_builtin,
                                                         args=(str(tmp_path / "cache"),))
    with open(root.with_name(root.name + ".lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        child.start()
        waiting = _blocked_on_a_lock(child.pid) and not list(root.rglob("*.png"))
    child.join(120)
    if child.is_alive():
        child.kill()
        child.join()
    assert waiting and child.exitcode == 0
    alone = generate_repository(tmp_path / "alone", seed=6, per_category=4, size=64)
    assert _tree(root) == _tree(alone) and not list(root.rglob("*.tmp"))


def test_a_complete_builtin_repository_is_read_without_its_lock(tmp_path, monkeypatch):
    """A finished repository in a cache this process may not write (another user's, or
    read-only) is used as it is; one with images missing is a one-line error naming
    $GLSYNTH_CACHE."""
    from glsynth.appearance import repository
    from glsynth.core.errors import UserError

    monkeypatch.setenv("GLSYNTH_CACHE", str(tmp_path / "cache"))
    root = repository.builtin_repository(seed=6, per_category=2, size=32)
    root.with_name(root.name + ".lock").unlink()

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr("builtins.open", refused)
    assert repository.builtin_repository(seed=6, per_category=2, size=32) == root
    next(root.rglob("*.png")).unlink()
    with pytest.raises(UserError, match=r"^\$GLSYNTH_CACHE: cannot make .*Permission denied"):
        repository.builtin_repository(seed=6, per_category=2, size=32)
