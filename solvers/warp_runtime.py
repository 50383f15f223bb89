"""One place that initialises warp: quiet output and a kernel cache inside the project's cache folder."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import warp as wp

_done = False


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
    wp.init()
    _done = True


class RecordedLaunch:
    """A kernel's launch recorded once (`wp.launch(record_cmd=True)`) and relaunched, its size and scalar arguments
    set only when they change: on the CPU a fresh launch with fifteen arguments costs some 50 us, a relaunch some 8,
    and setting one argument or the size some 5 (warp packs it anew each time)."""

    def __init__(self, kernel: wp.Kernel, dim: int, inputs: list, device: str) -> None:
        init_warp()
        self.cmd = wp.launch(kernel, dim, inputs=inputs, device=device, record_cmd=True)
        self.labels = [arg.label for arg in kernel.adj.args]
        self._dim = dim
        self._values = {i: v for i, v in enumerate(inputs) if isinstance(v, (bool, int, float))}

    def set(self, index: int, value: bool | int | float) -> None:
        """Set the scalar argument at `index` (its position in the kernel's signature) to value, if it differs."""
        if self._values.get(index) != value:
            self.cmd.set_param_at_index(index, value)
            self._values[index] = value

    def launch(self, dim: int) -> None:
        """Launch over dim threads."""
        if dim != self._dim:
            self.cmd.set_dim(dim)
            self._dim = dim
        self.cmd.launch()
