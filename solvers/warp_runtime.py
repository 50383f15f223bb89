"""One place that initialises warp (quiet output and a kernel cache inside the project's cache folder), records and
relaunches a kernel's launch, and finds a kernel a term names and its arguments by name."""

from __future__ import annotations

import ctypes
import importlib
import logging
import os
import sys
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

import warp as wp

try:  # warp's builder of a CPU launch's argument structure (`RecordedLaunch`); private, so optional
    from warp._src.context import _build_cpu_args_structs
except ImportError:  # pragma: no cover - another warp version: relaunch through the recorded command
    _build_cpu_args_structs = None

_done = False

#: What warp's native library prints (to the process's stderr, at every `wp.init()`) on a machine without a CUDA
#: driver: no news on a CPU machine, and a process pool's workers would print it once each.
NO_CUDA_DRIVER = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"


def cache_root() -> Path:
    """The project's cache folder: $FRICTIONBENCH_CACHE, else ~/.cache/frictionbench."""
    return Path(os.environ.get("FRICTIONBENCH_CACHE", Path.home() / ".cache" / "frictionbench"))


def init_warp() -> None:
    """Initialise warp once, caching compiled kernels under cache_root()/warp (reused across runs and CI)."""
    global _done
    if _done:
        return
    wp.config.kernel_cache_dir = str(cache_root() / "warp")
    wp.config.log_level = logging.WARNING  # no init banner or per-module load lines
    without_lines(NO_CUDA_DRIVER, wp.init)
    _done = True


def without_lines(prefix: str, call: Callable[[], None]) -> None:
    """Run call() with the process's stderr (file descriptor 2, where native code writes) captured, then write back
    everything it printed except the lines that start with `prefix`."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            call()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            text = captured.read().decode(errors="replace")
            sys.stderr.write("".join(line for line in text.splitlines(keepends=True) if not line.startswith(prefix)))
            sys.stderr.flush()


class RecordedLaunch:
    """A kernel's launch recorded once (`wp.launch(record_cmd=True)`) and relaunched, its size and scalar arguments
    set only when they change: on the CPU a fresh launch with fifteen arguments costs some 50 us, a relaunch some 8,
    and setting one argument or the size some 5 (warp packs it anew each time).

    On the CPU a relaunch of the recorded command still builds its argument structure anew (3.5 us with fifteen
    arguments, where the kernel over 160 contact points runs 3-10 us): here it is built once, by the function warp's
    own relaunch builds it with (`_build_cpu_args_structs`), and again only after a `set` or a new size, and the
    compiled kernel is called on it directly (0.13 us): the same kernel on the same arguments, so the same results
    bit for bit (tests/test_warp_runtime.py). Where that function is not there (another warp version) or on CUDA,
    the recorded command relaunches itself."""

    def __init__(self, kernel: wp.Kernel, dim: int, inputs: list, device: str) -> None:
        init_warp()
        self.cmd = wp.launch(kernel, dim, inputs=inputs, device=device, record_cmd=True)
        self.labels = [arg.label for arg in kernel.adj.args]
        self._dim = dim
        self._values = {i: v for i, v in enumerate(inputs) if isinstance(v, (bool, int, float))}
        cmd = self.cmd
        self._direct = (_build_cpu_args_structs is not None and cmd.device.is_cpu and cmd.block_dim <= 1
                        and not cmd.adjoint)  # the compiled kernel called on the structure built once
        self._packed: tuple | None = None  # with _direct: (kernel entry, bounds, arguments, their reference)

    def set(self, index: int, value: bool | int | float) -> None:
        """Set the scalar argument at `index` (its position in the kernel's signature) to value, if it differs."""
        if self._values.get(index) != value:
            self.cmd.set_param_at_index(index, value)
            self._values[index] = value
            self._packed = None

    def launch(self, dim: int) -> None:
        """Launch over dim threads."""
        if dim != self._dim:
            self.cmd.set_dim(dim)
            self._dim = dim
            self._packed = None
        cmd = self.cmd
        if not self._direct:
            cmd.launch()
            return
        if self._packed is None:
            args, _ = _build_cpu_args_structs(cmd.kernel, cmd.hooks, cmd.params, False)
            self._packed = cmd.hooks.forward, ctypes.byref(cmd.params[0]), args, ctypes.byref(args)
        forward, bounds, _, args = self._packed
        forward(bounds, args)


class Relaunches:
    """Every distinct launch a backend makes, recorded at its first (`RecordedLaunch`) and relaunched after with its
    scalar arguments set: a launch is told apart by its kernel, its size and its other arguments (warp arrays and
    vectors) by identity, so those must be long-lived objects (a solver's buffers), not ones made anew for each
    launch; each is kept referenced here, so that its identity stays its own. A fresh `wp.launch` on the CPU packs
    every argument anew (25-50 us with the contact kernels' fifteen), a relaunch sets what changed (1-2 us): on a
    660-vertex mesh, where a Newton iteration launches some twenty kernels, the packing was about a sixth of a truth
    step (docs/results.md, "The truth step"). The same kernel on the same arguments: the same results bit for bit
    (tests/test_warp_runtime.py)."""

    def __init__(self, device: str | wp.Device) -> None:
        self.device = str(device)
        self._recorded: dict[tuple, tuple[RecordedLaunch, list]] = {}

    def launch(self, kernel: wp.Kernel, dim: int, inputs: list) -> None:
        """`wp.launch(kernel, dim, inputs=inputs)` on the device, through its recording (dim 0: nothing to run)."""
        if dim == 0:
            return
        scalars = [(i, v) for i, v in enumerate(inputs) if isinstance(v, (bool, int, float))]
        key = (kernel, dim, *(id(v) for v in inputs if not isinstance(v, (bool, int, float))))
        entry = self._recorded.get(key)
        if entry is None:
            entry = self._recorded[key] = (RecordedLaunch(kernel, dim, inputs, self.device), list(inputs))
        recorded = entry[0]
        for i, v in scalars:
            recorded.set(i, v)
        recorded.launch(dim)


def kernel_named(name: str, module: str) -> wp.Kernel:
    """The warp kernel a term names (`solvers.physics.terms`): "module:attr", or a bare attribute of `module`."""
    where, _, attr = name.rpartition(":")
    return getattr(importlib.import_module(where or module), attr)


def kernel_inputs(kernel: wp.Kernel, values: Mapping[str, object], what: str) -> list:
    """`kernel`'s arguments in its signature's order, each taken from `values` by its name; ValueError naming the
    ones `values` lacks, and `what` (the term)."""
    labels = [arg.label for arg in kernel.adj.args]
    missing = [label for label in labels if label not in values]
    if missing:
        raise ValueError(f"{what}: kernel {kernel.key} takes {missing}, which neither the backend nor the term's "
                         f"kernel_parameters provides")
    return [values[label] for label in labels]
