"""Pluggable executors for the matrix: a local process pool (default) or a Dask cluster.

Both give `slots` (how many runs keep every worker busy: the runner keeps that many in flight), `share(obj) ->
handle` (a large argument sent once per worker, passed to `submit` in place of the object), `submit(fn, *args) ->
future`, `as_completed(futures)` and `abandon(futures)` (the last runs in flight, whose results are not wanted,
stopped as the executor closes); the runner uses nothing else. Tasks read and
write no files of the client's (`bench.payload`): a Dask worker may share no filesystem with it.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures import as_completed as cf_as_completed


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the platform has one, else the CPU count)."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity else (os.cpu_count() or 1)


class ProcessExecutor:
    """A local pool of `jobs` worker processes (spawned: warp and torch do not survive a fork)."""

    def __init__(self, jobs: int) -> None:
        self.pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"))
        self.slots = jobs
        self.abandoned = False

    @staticmethod
    def share(obj: object) -> object:
        """The object itself: a local worker receives its own copy with each task (pickled through a pipe)."""
        return obj

    def submit(self, fn, *args) -> Future:
        """Schedule fn(*args)."""
        return self.pool.submit(fn, *args)

    @staticmethod
    def as_completed(futures: Iterable[Future]) -> Iterator[Future]:
        """Futures in completion order."""
        return cf_as_completed(list(futures))

    def abandon(self, futures: Iterable[Future]) -> None:
        """The runs in flight are not wanted: the pool's workers are stopped when it closes, not waited for (the
        pool is used for nothing else after)."""
        self.abandoned = True

    def __enter__(self) -> "ProcessExecutor":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        stop = exc_type is not None or self.abandoned
        if stop:  # interrupted (Ctrl-C, SIGTERM, an error) or abandoned: stop the runs in flight now, not when they
            # end; what is stored stays and a rerun resumes (Python >= 3.14 has terminate_workers)
            for process in list((getattr(self.pool, "_processes", None) or {}).values()):
                process.terminate()
        self.pool.shutdown(wait=not stop, cancel_futures=True)


class DaskExecutor:
    """A Dask distributed client: `address` of a running scheduler (env FRICTIONBENCH_DASK_SCHEDULER), or a
    LocalCluster of `jobs` single-threaded worker processes started for the run. Its `slots`: `jobs`, or on a
    running scheduler the worker threads it has when the run starts where they are more."""

    def __init__(self, jobs: int, address: str | None = None) -> None:
        from dask.distributed import Client, LocalCluster

        address = address or os.environ.get("FRICTIONBENCH_DASK_SCHEDULER")
        self.cluster = None if address else LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                                         dashboard_address=None)
        self.client = Client(address or self.cluster)
        self.slots = max(jobs, sum(self.client.nthreads().values())) if address else jobs

    def share(self, obj: object):
        """`obj` scattered to every worker once (a future; tasks given it receive the object, and a worker that
        joins later or lost its copy fetches it from a peer)."""
        return self.client.scatter(obj, broadcast=True, hash=False)

    def submit(self, fn, *args):
        """Schedule fn(*args) on the cluster (pure=False: every submission runs; a task whose worker dies is
        rescheduled on another one)."""
        return self.client.submit(fn, *args, pure=False)

    @staticmethod
    def as_completed(futures):
        """Futures in completion order."""
        from dask.distributed import as_completed

        return as_completed(list(futures))

    def abandon(self, futures) -> None:
        """The runs of `futures` are not wanted: cancelled (a worker running one finishes it, and its result is
        dropped)."""
        self.client.cancel(list(futures))

    def __enter__(self) -> "DaskExecutor":
        return self

    def __exit__(self, *exc) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(kind: str, jobs: int):
    """`process` (local pool) or `dask` (see DaskExecutor)."""
    if kind == "process":
        return ProcessExecutor(jobs)
    if kind == "dask":
        return DaskExecutor(jobs)
    raise ValueError(f"executor = {kind!r}: expected 'process' or 'dask'")
