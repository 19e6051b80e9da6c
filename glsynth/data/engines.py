"""How generation units run: in this process, in a local pool, or on a Ray cluster.

Every engine runs the same ``run_task`` on units (one environment, or a run of plates), each
worker holding one GL context; units write their own files and marker, so the dataset does not
depend on the engine, the worker count or the order units finish in. The driver merges the
markers into the manifests (glsynth/data/dataset.py).
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import TYPE_CHECKING

from glsynth.core.children import die_with_parent
from glsynth.core.config import Config
from glsynth.core.errors import UserError, shown
from glsynth.core.runlock import RunLock

if TYPE_CHECKING:
    from glsynth.data.dataset import Task
# dataset (and with it trimesh, scipy and networkx, 0.5 s) is imported where units are found
# or run, not here: the command line reads ENGINES, and every command would start 0.5 s later.

ENGINES = ("local", "ray")


class GenerationWorker:
    """One GL context and the run's settings; a pool process or a Ray actor holds one.
    ``separate`` workers (other processes than the driver) hold the run folder's worker lock
    while they live, so a new run cannot start before they are gone."""

    def __init__(self, config: Config, root_seed: int, out: str, separate: bool = False
                 ) -> None:
        from glsynth.data.dataset import check_run_folder
        from glsynth.render.gl.renderer import Renderer

        self.config, self.root_seed, self.out = config, root_seed, Path(out)
        check_run_folder(self.out, config, root_seed)
        self.lock = RunLock(self.out, worker=True).acquire() if separate else None
        self.renderer = Renderer(config.render)

    def run(self, task: Task) -> dict:
        from glsynth.data.dataset import run_task

        return run_task(self.config, self.root_seed, task, self.out, self.renderer)

    def release(self) -> None:
        self.renderer.release()
        if self.lock is not None:
            self.lock.release()


def check_engine(engine: str, workers: int, address: str | None) -> None:
    if engine not in ENGINES:
        raise UserError(f"--engine {engine!r}: choose one of {', '.join(ENGINES)}")
    if workers < 1:
        raise UserError(f"--workers {workers}: give at least 1")
    if address is not None and engine != "ray":
        raise UserError("--address is for --engine ray; drop it or add --engine ray")
    if address is not None and not RAY_ADDRESS.fullmatch(address):
        raise UserError(f"--address {shown(address)}: write auto, HOST:PORT or "
                        "ray://HOST:PORT (e.g. 10.0.0.5:6379), or leave it out for a local Ray")


RAY_ADDRESS = re.compile(r"auto|(ray://)?[A-Za-z0-9_.\-]+:(6553[0-5]|655[0-2]\d|65[0-4]\d\d|"
                         r"6[0-4]\d{3}|[1-5]\d{4}|[1-9]\d{0,3})")
"""The addresses ray.init takes: auto, or a host and port, with ray:// for Ray Client."""


def execute(config: Config, root_seed: int, out: Path, workers: int, engine: str = "local",
            address: str | None = None) -> Iterator[dict]:
    """Run the units that have no marker yet; yields each finished unit's result."""
    from glsynth.data.dataset import pending_tasks

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


# The pool process's worker, or the error that stopped it from starting: the first unit it is
# given raises that error in the driver, which then ends the run with it (a pool that restarted
# failing workers would never end).
_PROCESS_WORKER: list[GenerationWorker | BaseException] = []


def _init_process(config: Config, root_seed: int, out: str, driver: int) -> None:
    die_with_parent(driver)  # so no unit outlives its run
    try:
        _PROCESS_WORKER.append(GenerationWorker(config, root_seed, out, separate=True))
    except Exception as error:  # reported by the first unit, in the driver
        _PROCESS_WORKER.append(error)


def _run_in_process(task: Task) -> dict:
    worker = _PROCESS_WORKER[0]
    if isinstance(worker, BaseException):
        raise worker
    return worker.run(task)


def _pool(config: Config, root_seed: int, out: Path, workers: int,
          pending: list[Task]) -> Iterator[dict]:
    """Units on ``workers`` spawned processes. The first failure, a worker that could not
    start or one that died, ends the run at once: the other workers are stopped."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")  # fork and GL contexts do not mix
    pool = ProcessPoolExecutor(workers, ctx, _init_process,
                               (config, root_seed, str(out), os.getpid()))
    futures: set[Future] = {pool.submit(_run_in_process, task) for task in pending}
    try:
        while futures:
            done, futures = wait(futures, return_when=FIRST_COMPLETED)
            for future in done:
                try:
                    result = future.result()
                except BrokenProcessPool as error:
                    raise UserError("a worker process died (killed, or out of memory?); run "
                                    "the same command again to resume, with fewer --workers "
                                    "if memory is short") from error
                yield result
    finally:
        if futures:  # stopped early: do not wait for units still rendering
            for process in list(pool._processes.values()):  # no public way in Python 3.11
                process.kill()
        pool.shutdown(wait=True, cancel_futures=True)


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
        raise UserError("--engine ray needs Ray: .venv/bin/pip install 'glsynth[ray]' "
                        "(scripts/install.sh installs it)") from error
    env_vars = {k: v for k, v in os.environ.items() if k.startswith("GLSYNTH_")}
    started_here = not ray.is_initialized()
    if started_here:
        # Ray's own log lines reach the terminal only under --debug (a root logger at DEBUG).
        quiet = not logging.getLogger().isEnabledFor(logging.DEBUG)
        options = dict(runtime_env={"env_vars": env_vars}, log_to_driver=True,
                       logging_level=logging.ERROR if quiet else logging.INFO)
        if address is None:
            options.update(num_cpus=workers, include_dashboard=False)
        try:
            ray.init(address=address, **options)
        except (ConnectionError, RuntimeError, TimeoutError, ValueError) as err:
            reason = (str(err).splitlines() or [type(err).__name__])[0][:120]
            raise UserError(f"--address {address}: Ray could not start or connect "
                            f"({reason}); check the address, or start the cluster with "
                            "ray start --head") from None
    try:
        actor = ray.remote(num_cpus=1)(GenerationWorker)
        pool = ActorPool([actor.remote(config, root_seed, str(out.resolve()), True)
                          for _ in range(workers)])
        yield from pool.map_unordered(lambda a, task: a.run.remote(task), pending)
    finally:
        if started_here:
            ray.shutdown()
