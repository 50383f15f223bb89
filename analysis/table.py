"""The results table: one row per scenario x solver variant, written as `results.csv`.

Column order (docs/metrics.md), from the schema (`analysis.schema.COLUMNS`, read when the table is written):
1. identity: the placed identity columns present in the rows, then solver parameters (keys starting with `param_`,
   in the order first seen);
2. metrics: the other placed columns present in the rows, then any other key (the schema's unplaced columns among
   them) in the order first seen;
3. provenance: the placed provenance columns present in the rows, then any other `*_version` key.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import os
import platform
import shutil
import subprocess
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import pandas as pd

from frictionbench.analysis.schema import VERSIONED_PACKAGES, names
from frictionbench.scenarios.atomic import write_text_atomic

#: The identity columns (`analysis.schema`): a row's key across result sets.
IDENTITY_COLUMNS: tuple[str, ...] = names("identity")
PARAM_PREFIX = "param_"
#: Timing [s, ms or ratios of them], measured on this machine: never compared for behaviour.
TIMING_COLUMNS: tuple[str, ...] = names("timing")
#: Provenance written once per table (`provenance()`), the table's last columns.
PROVENANCE_COLUMNS: tuple[str, ...] = names("provenance", placed=True)


def column_order(keys: Iterable[str]) -> list[str]:
    """The keys of the results rows in table order: identity, parameters, metrics, provenance (see module doc)."""
    keys = list(dict.fromkeys(keys))
    identity, provenance_columns = names("identity", placed=True), names("provenance", placed=True)
    metric_columns = [c for c in names(placed=True) if c not in identity and c not in provenance_columns]
    known = set(identity) | set(metric_columns) | set(provenance_columns)
    params = [k for k in keys if k.startswith(PARAM_PREFIX)]
    extra_provenance = [k for k in keys if k.endswith("_version") and k not in known]
    other = [k for k in keys if k not in known and k not in params and k not in extra_provenance]
    present = set(keys)
    return ([k for k in identity if k in present] + params
            + [k for k in metric_columns if k in present] + other
            + [k for k in provenance_columns if k in present] + extra_provenance)


def _git(*args: str) -> str | None:
    """Output of `git args...` run in this package's source tree, or None outside a repository."""
    if shutil.which("git") is None:
        return None
    root = Path(__file__).resolve().parents[1]
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def _cpu_name() -> str:
    """The CPU model from /proc/cpuinfo (Linux), else `platform.processor()`."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _gpu_name() -> str:
    """The first GPU's name: from torch when the caller already imported it, else from nvidia-smi; '' if none.

    torch is never imported here (that costs seconds); it is only asked when `sys.modules` already holds it.
    """
    torch = sys.modules.get("torch")
    if torch is not None and torch.cuda.is_available():
        return str(torch.cuda.get_device_name(0))
    if shutil.which("nvidia-smi") is None:
        return ""
    try:
        done = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                              capture_output=True, text=True, timeout=20, check=False)
    except (OSError, subprocess.SubprocessError):
        return ""
    return done.stdout.strip().splitlines()[0] if done.returncode == 0 and done.stdout.strip() else ""


def provenance(device: str = "", gpu_name: str | None = None) -> dict[str, str | bool]:
    """Where and with what the results were made, keyed by `PROVENANCE_COLUMNS`.

    device: the device the solvers ran on (`cpu`, `cuda:0`, ...), recorded as given.
    gpu_name: the GPU's name; None looks it up (torch if already imported, else nvidia-smi; '' when none).
    commit is the git HEAD of this source tree ('' outside a repository), commit_dirty whether tracked files
    differ from it. Package versions come from the installed distributions' metadata ('' if not installed);
    no package is imported.
    """
    commit = _git("rev-parse", "HEAD")
    info: dict[str, str | bool] = {
        "commit": commit or "",
        "commit_dirty": bool(_git("status", "--porcelain", "--untracked-files=no")) if commit else False,
        "timestamp_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "device": device,
        "cpu_name": _cpu_name(),
        "gpu_name": _gpu_name() if gpu_name is None else gpu_name,
        "platform": platform.platform(),
        "python_version": platform.python_version(),
    }
    for dist, column in VERSIONED_PACKAGES.items():
        try:
            info[column] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            info[column] = ""
    return info


def results_frame(rows: Sequence[Mapping[str, object]],
                  provenance_info: Mapping[str, object] | None = None) -> pd.DataFrame:
    """Rows as a DataFrame in `column_order`; provenance_info fills provenance keys a row does not have."""
    filled = [{**(provenance_info or {}), **row} for row in rows]
    keys = [k for row in filled for k in row]
    return pd.DataFrame(filled, columns=column_order(keys))


def write_results_csv(rows: Sequence[Mapping[str, object]], path: str | os.PathLike,
                      provenance_info: Mapping[str, object] | None = None) -> Path:
    """Write rows to `path` as CSV in `column_order`, atomically (temporary file renamed into place).

    provenance_info: values for the provenance columns, default `provenance()`; a row's own values win (a row
    may carry its own `device`). Missing values are empty cells. Returns the path.
    """
    frame = results_frame(rows, provenance() if provenance_info is None else provenance_info)
    return write_text_atomic(path, frame.to_csv(index=False))


def variant_labels(frame: pd.DataFrame) -> pd.Series:
    """`solver/variant` per row (`solver` alone where the variant is empty or missing)."""
    solver = frame["solver"].fillna("").astype(str)
    if "variant" not in frame:
        return solver
    variant = frame["variant"].fillna("").astype(str)
    return solver.where(variant == "", solver + "/" + variant)
