"""Is behaviour unchanged? Compare two results folders of one suite, or run the suite on a base commit and on the
working tree first and compare those.

    python -m frictionbench.bench.unchanged --base 1ecc70a --suite quick --out out/unchanged  # runs both, compares
    python -m frictionbench.bench.unchanged OLD_DIR NEW_DIR                                   # two results folders
    python -m frictionbench.bench.unchanged --base 239aabc --suite quick:quick-undamped       # a renamed suite

A suite renamed between the two (`OLD:NEW`) is compared member by member: the old rows' suite and scenario names
are renamed to the new ones first, and both sides are judged by the new name's gates.

Rows are matched by their identity columns (suite, scenario, split, mesh, train_mesh, solver, variant). Every
other column is compared except timing and provenance (`IGNORED_COLUMNS`, `*_version`): numbers to a relative
tolerance, 1e-9 for the rows of the exact solvers (`--exact`, default the full-space solver) and 1e-6 for the
others (reduced solvers: their training and cubature add round-off), booleans and text exactly (in text, each
folder's path and the 16-digit run and model keys, which hash paths, are masked), two missing values are
equal. The verdicts of the shipped gates (or `--gates`) must agree row by row, except those of gates on timing
columns. A row or a compared column that one side lacks is a difference; a column only the new side has is
listed as a note. Prints a summary and exits 1 on any difference, 0 when none.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from frictionbench.analysis.schema import is_missing, names
from frictionbench.analysis.table import IDENTITY_COLUMNS
from frictionbench.bench.gates import check, load_gates
from frictionbench.bench.store import load_run_info
from frictionbench.scenarios.suites import load_suite

#: Columns never compared: measured times (and what is derived from them) and provenance (`analysis.schema` kinds
#: timing and provenance).
IGNORED_COLUMNS: frozenset[str] = frozenset(names("timing", "provenance"))
EXACT_RTOL = 1e-9
REDUCED_RTOL = 1e-6
#: Absolute floor of the comparison: values within it of each other are equal whatever their ratio.
ATOL = 1e-12
#: A run or model key in a text (e.g. a failure naming a model file): 16 hex digits, a hash of settings and paths.
KEY = re.compile(r"\b[0-9a-f]{16}\b")


@dataclass(frozen=True)
class Difference:
    """One thing that differs: where (row identity or gate), what (column), the two values."""

    where: str
    what: str
    old: object
    new: object

    def __str__(self) -> str:
        return f"{self.where}: {self.what}: {self.old!r} -> {self.new!r}"


def values_equal(old: object, new: object, rtol: float, atol: float = ATOL) -> bool:
    """Equal within rtol (relative to the larger magnitude) or atol for numbers; exact for anything else; two
    missing values (None, NaN, empty cell) are equal, and so are two infinities of one sign."""
    if is_missing(old) or is_missing(new):
        return is_missing(old) and is_missing(new)
    if isinstance(old, bool) or isinstance(new, bool) or isinstance(old, str) or isinstance(new, str):
        return str(old).lower() == str(new).lower()
    return math.isclose(float(old), float(new), rel_tol=rtol, abs_tol=atol)


def _identity(frame: pd.DataFrame) -> list[str]:
    return [c for c in IDENTITY_COLUMNS if c in frame]


def _keyed(frame: pd.DataFrame, keys: list[str]) -> dict[tuple, dict]:
    """Rows by their identity; raises ValueError on a repeated identity (the rows could not be matched)."""
    rows: dict[tuple, dict] = {}
    for row in frame.to_dict("records"):
        key = tuple("" if is_missing(row[k]) else str(row[k]) for k in keys)
        if key in rows:
            raise ValueError(f"two rows share the identity {dict(zip(keys, key))}")
        rows[key] = row
    return rows


def compare_results(old: pd.DataFrame, new: pd.DataFrame, exact_solvers: Sequence[str] = ("full",),
                    exact_rtol: float = EXACT_RTOL, rtol: float = REDUCED_RTOL) -> tuple[list[Difference], list[str]]:
    """(differences, notes) between two results tables (see the module doc)."""
    keys = _identity(old)
    if keys != _identity(new):
        return [Difference("table", "identity columns", keys, _identity(new))], []
    compared = [c for c in old.columns if c not in keys and c not in IGNORED_COLUMNS and not c.endswith("_version")]
    differences = [Difference("table", "column missing", c, None) for c in compared if c not in new]
    notes = [f"new column {c}" for c in new.columns if c not in old and c not in IGNORED_COLUMNS
             and not c.endswith("_version")]
    a, b = _keyed(old, keys), _keyed(new, keys)
    differences += [Difference(_where(keys, k), "row", "present", "missing") for k in a if k not in b]
    differences += [Difference(_where(keys, k), "row", "missing", "present") for k in b if k not in a]
    for key in (k for k in a if k in b):
        tol = exact_rtol if a[key].get("solver") in exact_solvers else rtol
        for column in (c for c in compared if c in new):
            if not values_equal(a[key][column], b[key][column], tol):
                differences.append(Difference(_where(keys, key), column, a[key][column], b[key][column]))
    return differences, notes


def _where(keys: list[str], key: tuple) -> str:
    return " ".join(f"{k}={v}" for k, v in zip(keys, key) if k in ("scenario", "mesh", "solver", "variant"))


def compare_verdicts(old: pd.DataFrame, new: pd.DataFrame, suite: str, gates: list[dict]) -> list[Difference]:
    """Gate verdicts that differ between the two tables (a verdict only one side has included); gates on
    timing columns (`IGNORED_COLUMNS`) are not judged: their verdicts depend on the machine's load."""
    gates = [g for g in gates if g.get("metric") not in IGNORED_COLUMNS]

    def verdicts(frame: pd.DataFrame) -> dict[tuple, str]:
        return {(v.gate, v.scenario, v.variant, v.metric): v.status for v in check(frame, gates, suite)}

    a, b = verdicts(old), verdicts(new)
    return [Difference(f"gate {k[0]} on {k[1]} [{k[2]}]", k[3], a.get(k), b.get(k))
            for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


def compare_folders(old_dir: Path, new_dir: Path, exact_solvers: Sequence[str], gates_file: str | None,
                    renamed: tuple[str, str] | None = None) -> tuple[list[Difference], list[str], int]:
    """(differences, notes, rows compared) between two results folders of the same suite (`renamed`: (old name,
    new name) of a suite renamed between them, the old rows renamed first)."""
    old, new = (_masked(pd.read_csv(d / "results.csv"), (old_dir, new_dir)) for d in (old_dir, new_dir))
    suites = {load_run_info(d)["suite"] for d in (old_dir, new_dir)}
    if renamed is not None:
        was, now = renamed
        old = old.assign(suite=old["suite"].replace(was, now),
                         scenario=old["scenario"].str.replace(f"{was}/", f"{now}/", n=1, regex=False))
        suites = {now if name == was else name for name in suites}
    if len(suites) != 1:
        raise ValueError(f"the folders hold different suites: {sorted(suites)}")
    differences, notes = compare_results(old, new, exact_solvers)
    differences += compare_verdicts(old, new, load_suite(suites.pop()).name, load_gates(gates_file))
    return differences, notes, len(old)


def _masked(frame: pd.DataFrame, folders: Sequence[Path]) -> pd.DataFrame:
    """The table with, in its text cells, the results folders' paths replaced by `<out>` and run and model keys by
    `<key>`: they differ between two runs of the same code."""
    paths = sorted({p for f in folders for p in (str(f), str(f.resolve()))}, key=len, reverse=True)

    def mask(value: object) -> object:
        if not isinstance(value, str):
            return value
        for path in paths:
            value = value.replace(path, "<out>")
        return KEY.sub("<key>", value)

    return frame.map(mask)


def run_suite_at(source: Path, suite: str, out: Path, jobs: int) -> Path:
    """Run `suite` with the code in `source` (a checkout) into `out`; returns out. A checkout from before the one
    import name (no frictionbench/ folder: its packages were top-level) runs its command line as `bench.cli`."""
    env = os.environ | {"PYTHONPATH": str(source)}
    cli = "frictionbench.bench.cli" if (source / "frictionbench" / "__init__.py").is_file() else "bench.cli"
    cmd = [sys.executable, "-m", cli, "run", "--suite", suite, "--out", str(out), "--jobs", str(jobs), "--no-report"]
    print("running:", " ".join(cmd), f"(in {source})", flush=True)
    subprocess.run(cmd, cwd=source, env=env, check=True)
    return out


def run_base_and_tree(base: str, suite: str, out: Path, jobs: int, renamed: str = "") -> tuple[Path, Path]:
    """Run the suite on commit `base` (a temporary git worktree) and on this working tree (there named `renamed`
    where given), into out/base and out/tree; returns both folders."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory(prefix="unchanged-") as tmp:
        checkout = Path(tmp) / "base"
        subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", str(checkout), base], check=True)
        try:
            run_suite_at(checkout, suite, out / "base", jobs)
        finally:
            subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(checkout)], check=False)
    return out / "base", run_suite_at(root, renamed or suite, out / "tree", jobs)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m frictionbench.bench.unchanged", description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="*", type=Path, help="OLD_DIR NEW_DIR: two results folders to compare")
    p.add_argument("--base", help="a git revision: run the suite on it and on the working tree, then compare")
    p.add_argument("--suite", default="quick", help="the suite, or OLD:NEW for one renamed since --base")
    p.add_argument("--out", type=Path, help="with --base: where the two runs go (default: a folder under out/)")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--exact", nargs="+", default=["full"], help="solvers compared to 1e-9 (default: full)")
    p.add_argument("--gates", help="gates file (default: the shipped gates.toml)")
    args = p.parse_args(argv)
    if bool(args.base) == (len(args.folders) == 2) or len(args.folders) not in (0, 2):
        p.error("give either --base REV or two results folders")
    was, _, now = args.suite.partition(":")
    renamed = (was, now) if now else None
    if args.base:
        old_dir, new_dir = run_base_and_tree(args.base, was, args.out or Path("out") / "unchanged", args.jobs, now)
    else:
        old_dir, new_dir = args.folders
    differences, notes, rows = compare_folders(old_dir, new_dir, args.exact, args.gates, renamed)
    for note in notes:
        print("note:", note)
    for difference in differences:
        print("DIFFERENT", difference)
    print(f"compared {rows} rows of {old_dir} (old) and {new_dir} (new): "
          + ("unchanged" if not differences else f"{len(differences)} differences"))
    return 1 if differences else 0


if __name__ == "__main__":
    raise SystemExit(main())
