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
