"""How generation units run: in this process, in a local pool, or on a Ray cluster.

Every engine runs the same ``run_task`` on units (one environment, or a run of plates), each
worker holding one GL context; units write their own files and marker, so the dataset does not
depend on the engine, the worker count or the order units finish in. The driver merges the
markers into the manifests (glsynth/data/dataset.py).
"""

import os
from collections.abc import Iterator
from pathlib import Path

from glsynth.core.config import Config
from glsynth.data.dataset import Task, check_run_folder, pending_tasks, run_task

ENGINES = ("local", "ray")


class GenerationWorker:
    """One GL context and the run's settings; a pool process or a Ray actor holds one."""

    def __init__(self, config: Config, root_seed: int, out: str) -> None:
        from glsynth.render.gl.renderer import Renderer

        self.config, self.root_seed, self.out = config, root_seed, Path(out)
        check_run_folder(self.out, config, root_seed)
        self.renderer = Renderer(config.render)

    def run(self, task: Task) -> dict:
        return run_task(self.config, self.root_seed, task, self.out, self.renderer)

    def release(self) -> None:
        self.renderer.release()


def check_engine(engine: str, workers: int, address: str | None) -> None:
    if engine not in ENGINES:
        raise ValueError(f"--engine {engine!r}: choose one of {', '.join(ENGINES)}")
    if workers < 1:
        raise ValueError(f"--workers {workers}: give at least 1")
    if address is not None and engine != "ray":
        raise ValueError("--address is for --engine ray; drop it or add --engine ray")


def execute(config: Config, root_seed: int, out: Path, workers: int, engine: str = "local",
            address: str | None = None) -> Iterator[dict]:
    """Run the units that have no marker yet; yields each finished unit's result."""
    check_engine(engine, workers, address)
    pending = pending_tasks(config, out)
    if not pending:
        return
    if engine == "ray":
        yield from _ray(config, root_seed, out, workers, address, pending)
    elif workers == 1:
        worker = GenerationWorker(config, root_seed, str(out))
        try:
            for task in pending:
                yield worker.run(task)
        finally:
            worker.release()
    else:
        yield from _pool(config, root_seed, out, workers, pending)


_PROCESS_WORKER: list[GenerationWorker] = []


def _init_process(config: Config, root_seed: int, out: str) -> None:
    _PROCESS_WORKER.append(GenerationWorker(config, root_seed, out))


def _run_in_process(task: Task) -> dict:
    return _PROCESS_WORKER[0].run(task)


def _pool(config: Config, root_seed: int, out: Path, workers: int,
          pending: list[Task]) -> Iterator[dict]:
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")  # fork and GL contexts do not mix
    with ctx.Pool(workers, _init_process, (config, root_seed, str(out))) as pool:
        yield from pool.imap_unordered(_run_in_process, pending)


def _ray(config: Config, root_seed: int, out: Path, workers: int, address: str | None,
         pending: list[Task]) -> Iterator[dict]:
    """Shards by environment on Ray: ``workers`` actors, one GL context each.

    ``address`` None starts a local Ray instance with ``workers`` CPUs; otherwise it is handed
    to ``ray.init`` ('auto', 'host:6379', 'ray://host:10001'). On a cluster --out must be a
    shared filesystem at the same path on every node, and glsynth installed on every node; the
    actors check the first and say so.
    """
    try:
        import ray
        from ray.util import ActorPool
    except ImportError as error:
        raise RuntimeError("--engine ray needs Ray: .venv/bin/pip install 'glsynth[ray]' "
                           "(scripts/install.sh installs it)") from error
    env_vars = {k: v for k, v in os.environ.items() if k.startswith("GLSYNTH_")}
    started_here = not ray.is_initialized()
    if started_here:
        options = dict(runtime_env={"env_vars": env_vars}, log_to_driver=True)
        if address is None:
            options.update(num_cpus=workers, include_dashboard=False)
        ray.init(address=address, **options)
    try:
        actor = ray.remote(num_cpus=1)(GenerationWorker)
        pool = ActorPool([actor.remote(config, root_seed, str(out.resolve()))
                          for _ in range(workers)])
        yield from pool.map_unordered(lambda a, task: a.run.remote(task), pending)
    finally:
        if started_here:
            ray.shutdown()
