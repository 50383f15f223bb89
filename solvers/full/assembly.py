"""Per-element kernel launches split over disjoint element ranges, one Python thread each (CPU).

Warp's CPU backend runs a launch on one core, and it releases the GIL while the kernel runs, so launches on
disjoint element ranges from several threads run in parallel. A range's launch sees views of the per-element
arrays (inputs and outputs), so the threads write disjoint memory and the result is bitwise that of one launch.
On CUDA, or with one thread, it is one ordinary launch.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from functools import cache

import warp as wp
from threadpoolctl import threadpool_info

from frictionbench.solvers.warp_runtime import Relaunches

#: Fewest elements per range worth a thread of its own.
MIN_ELEMENTS_PER_THREAD = 1000


def thread_budget() -> int:
    """Threads the caller's thread-pool limits allow: the smallest thread count threadpoolctl reports among the
    loaded BLAS / OpenMP / MKL libraries (the runner's workers run under `threadpool_limits`), else the CPUs
    this process may use."""
    counts = [int(info["num_threads"]) for info in threadpool_info()]
    return max(1, min(counts, default=len(os.sched_getaffinity(0))))


@cache
def _pool(threads: int) -> ThreadPoolExecutor:
    """One shared pool per thread count, kept for the process (solvers come and go; their launches are short)."""
    return ThreadPoolExecutor(threads, thread_name_prefix="warp-cpu")


class ElementRanges:
    """m elements on `device` cut into up to `threads` contiguous ranges (one launch per range, in parallel), each
    range's launch recorded at its first and relaunched after (`solvers.warp_runtime.Relaunches`)."""

    def __init__(self, m: int, device: wp.Device, threads: int) -> None:
        k = 1 if device.is_cuda else max(1, min(threads, m // MIN_ELEMENTS_PER_THREAD))
        bounds = [m * i // k for i in range(k + 1)]
        self.ranges = list(zip(bounds[:-1], bounds[1:]))
        self.m, self.device = m, device
        self.launches = Relaunches(device)
        # (kernel, the whole inputs' identities) -> each range's inputs, cut once (views: the same memory)
        self._cuts: dict[tuple, tuple[list, list[list]]] = {}
        self._loaded: set[object] = set()

    @property
    def threads(self) -> int:
        """Number of ranges (threads) a launch uses."""
        return len(self.ranges)

    def launch(self, kernel: wp.Kernel, inputs: list, per_element: dict[int, int]) -> None:
        """`wp.launch(kernel, m, inputs=inputs)` over the ranges: input i in `per_element` is an array with
        per_element[i] consecutive rows per element (element e owns rows [k e, k (e + 1))), cut to the range;
        every other input is passed whole. The kernel must index those arrays by its thread id only.

        The calling thread runs the first range, pool threads the others. A kernel's first launch runs the ranges in
        turn: it may compile and load the kernel's module, which is done once, from one thread.
        """
        if len(self.ranges) == 1:
            self.launches.launch(kernel, self.m, inputs)
            return
        key = (kernel, *(id(x) for i, x in enumerate(inputs) if i in per_element))
        if key not in self._cuts:  # the whole arrays kept referenced, so that their identities stay theirs
            self._cuts[key] = (list(inputs), [
                [x[per_element[i] * a: per_element[i] * b] if i in per_element else x for i, x in enumerate(inputs)]
                for a, b in self.ranges])
        cuts = self._cuts[key][1]
        whole = [(i, x) for i, x in enumerate(inputs) if i not in per_element]

        def run(j: int) -> None:
            cut = cuts[j]
            for i, x in whole:  # the arguments passed whole may change (a scalar), the cut ones are the same
                cut[i] = x
            a, b = self.ranges[j]
            self.launches.launch(kernel, b - a, cut)

        if kernel not in self._loaded:
            for j in range(len(self.ranges)):
                run(j)
            self._loaded.add(kernel)
            return
        others = [_pool(len(self.ranges) - 1).submit(run, j) for j in range(1, len(self.ranges))]
        run(0)
        for f in others:
            f.result()
