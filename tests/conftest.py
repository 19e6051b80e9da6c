import dataclasses
import gc
from collections import Counter
from collections.abc import Generator

import pytest
from hypothesis import HealthCheck, settings

from glsynth.core.config import Config, EnvironmentConfig
from glsynth.world.environment import build_environment

pytest_plugins = ["fixtures_cracks"]
"""Shared fixtures kept in modules of their own, one per subject."""


def env_config(**environment) -> Config:
    """Default config with some [environment] fields replaced."""
    return dataclasses.replace(Config(), environment=EnvironmentConfig(**environment))


@pytest.fixture(scope="session")
def env0():
    return build_environment(Config(), root_seed=0, env_index=0)


@pytest.fixture(scope="session", autouse=True)
def isolated_cache(tmp_path_factory):
    """Texture repository, decoded-image and damage bank caches in a fresh folder for the test
    session, shared by its xdist workers (their base folders share a parent) as a dataset's
    workers share $GLSYNTH_CACHE: each repository is then made once a run, not once a
    worker (a repository is made under a lock; two workers may make the same damage bank
    entry at once, and its atomic writes make that harmless)."""
    import os

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    cache = shared / "glsynth-cache"
    cache.mkdir(exist_ok=True)
    previous = os.environ.get("GLSYNTH_CACHE")
    os.environ["GLSYNTH_CACHE"] = str(cache)
    yield
    if previous is None:
        os.environ.pop("GLSYNTH_CACHE", None)
    else:
        os.environ["GLSYNTH_CACHE"] = previous


SMALL = """
[dataset]
n_environments = 2
n_test_environments = 1
n_plates = 3
n_test_plates = 1
plates_per_task = 2
[cameras]
n_regular = 3
n_closeup = 2
[damage]
resolution = 64
[materials]
texture_size = 32
builtin_size = 64
images_per_category = 3
[render]
msaa = 0
shadow_map_px = 512
sky_visibility_maps = 4
sky_visibility_px = 256
[environment]
n_viaducts = 2
cutoff_factor = 1.0
"""
"""The tiny dataset's config: five cameras (three regular, two close-ups) and three plates for
the tests that train on it, read it or check its format. MSAA off and small shadow and sky maps
give the same labels at less cost (docs/results.md, "The test suite"); two viaducts an
environment, not ten, half the generation's CPU time."""


@pytest.fixture(scope="session")
def small_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "small.toml"
    path.write_text(SMALL)
    return path


QUICK = """
[dataset]
n_environments = 2
n_test_environments = 1
n_plates = 1
n_test_plates = 0
plates_per_task = 1
[cameras]
n_regular = 1
n_closeup = 1
[render]
msaa = 0
shadow_map_px = 512
sky_visibility_maps = 4
sky_visibility_px = 256
[damage]
resolution = 64
[materials]
texture_size = 32
builtin_size = 64
images_per_category = 3
[environment]
n_viaducts = 2
cutoff_factor = 1.0
"""
"""The cheapest run that still has two environments (one per split), a plate and the Tokaido
image size (generate refuses any other): for the tests of workers, locks and resuming, which
compare whole runs but not what is in the images. Two viaducts an environment: a generation
took 19 CPU-s with ten, 12 with two; one regular camera and one close-up (a frame of each
kind): 9.9 CPU-s a CLI generation, 12.8 with two regular cameras."""

settings.register_profile("full", max_examples=25, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.function_scoped_fixture])
settings.register_profile("quick", settings.get_profile("full"), max_examples=5)
"""Fuzz tests draw examples by these profiles (derandomized: a failure repeats); a test that
sets max_examples itself keeps it."""


def pytest_configure(config: pytest.Config) -> None:
    """The quick loop (-m "not slow") draws the quick profile's examples, the full suite the
    full profile's; --hypothesis-profile chooses another."""
    if config.getoption("hypothesis_profile", None) is None:
        quick = config.getoption("markexpr", "") == "not slow"
        settings.load_profile("quick" if quick else "full")


def pytest_collection_finish(session: pytest.Session) -> None:
    """What collection made (the test modules, their items, hypothesis and numpy state) lives
    all session: frozen out of the cyclic collector's sight, so that a full collection scans
    what the tests make since. The viewer asks for one at each opening
    (glsynth.view.worker.return_free_memory): in a worker it took 0.27 s, 3.3 s a quick loop."""
    gc.freeze()


DATASET_FIXTURES = {"tiny_dataset", "quick_dataset"}
"""Fixtures that generate a dataset: a test that uses one is marked slow."""


TINY_RUN_FILES = {"test_model.py", "test_assessment.py", "test_augment.py", "test_statistics.py"}
"""Files that train on the tiny dataset or read it most: scripts/test.sh's workers run them as
one unit, so the dataset is generated and tiny_run's networks trained on one worker only."""


def work_unit(nodeid: str) -> str:
    """What one worker runs whole under --dist loadfile: a file, or TINY_RUN_FILES together."""
    path = nodeid.split("::", 1)[0]
    return "tiny_run" if path.rsplit("/", 1)[-1] in TINY_RUN_FILES else path


@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> Generator[None, None, None]:
    """Dataset tests are slow. (Under scripts/test.sh's workers, pytest-xdist's --dist loadfile
    keeps each file on one worker, so its module fixtures are made once; a session dataset is
    made once on each worker that runs a file using it.)

    Then, once -m has deselected, the work units with the most slow tests come first, and
    among equals those with the most tests, each file's tests in their order: scripts/test.sh
    keeps this order (--no-loadscope-reorder), and the workers take units as they free, so the
    long ones start early and the short ones fill in at the end. pytest-xdist alone orders
    units by their count of tests, which put long one-test files last in the whole suite,
    a worker idle beside them (docs/results.md, "The test suite"); the quick loop, which has
    no slow tests, keeps that order."""
    for item in items:
        if DATASET_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
    result = yield
    units = Counter(work_unit(item.nodeid) for item in items)
    slow = Counter(work_unit(item.nodeid) for item in items if item.get_closest_marker("slow"))
    items.sort(key=lambda item: (-slow[work_unit(item.nodeid)], -units[work_unit(item.nodeid)]))
    return result


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """--dist loadfile, with TINY_RUN_FILES one unit (pytest-xdist's loadgroup cannot group
    files under pytest 9.2: see scripts/test.sh)."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class TinyRunTogether(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

    return TinyRunTogether(config, log)


def generate_into(out, config) -> int:
    """`glsynth generate --preset demo --seed 5` of the config file ``config`` into ``out``."""
    from glsynth.cli import main

    return main(["generate", "--preset", "demo", "--config", str(config), "--seed", "5",
                 "--out", str(out)])


@pytest.fixture(scope="session")
def quick_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "quick.toml"
    path.write_text(QUICK)
    return path


@pytest.fixture(scope="session")
def quick_dataset(quick_config, tmp_path_factory):
    """QUICK generated once (seed 5): the reference that reruns of it must equal byte for byte.
    Tests read it and never write into it (copy it first)."""
    out = tmp_path_factory.mktemp("quick") / "ds"
    assert generate_into(out, quick_config) == 0
    return out


@pytest.fixture(scope="session")
def tiny_dataset(small_config, tmp_path_factory):
    """A generated Tokaido-format dataset: 2 environments x 5 cameras at 1920x1080, 3 plates
    (seed 5). Tests read it and never write into it."""
    out = tmp_path_factory.mktemp("tiny") / "ds"
    assert generate_into(out, small_config) == 0
    return out


TINY_TRAINING = {
    "component": ["--image-size", "192x108", "--batch-size", "2", "--schedule", "1e-3:2",
                  "--loader-workers", "0", "--seed", "1"],
    "damage": ["--image-size", "192x108", "--batch-size", "4", "--schedule", "1e-3:1",
               "--loader-workers", "0", "--precision", "fp32"],
}
TINY_TRAINING["depth"] = TINY_TRAINING["damage"]
"""The small trainings on tiny_dataset: component for two epochs (test_model resumes it after
the first), damage and depth for one."""


@pytest.fixture(scope="session")
def tiny_run(tiny_dataset, tmp_path_factory):
    """``tiny_run(task)``: the run folder of TINY_TRAINING[task] on tiny_dataset, trained once
    a session, so test_model and test_assessment (one worker: TINY_RUN_FILES) share the three
    networks. Tests may evaluate into a run (its eval_* folders) but never train
    into it."""
    from glsynth.cli import main

    root = tmp_path_factory.mktemp("tiny-runs")
    done: dict[str, object] = {}

    def run(task: str):
        if task not in done:
            out = root / task
            assert main(["train", "--task", task, "--data", str(tiny_dataset), "--out",
                         str(out), *TINY_TRAINING[task]]) == 0
            done[task] = out
        return done[task]

    return run
