"""What an installed (non-editable) copy of the package carries: the shipped gates, suites and variant sets are package
data."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

from frictionbench.bench.gates import load_gates
from frictionbench.bench.matrix import variant_set

ROOT = Path(__file__).resolve().parents[1]


def test_the_shipped_gates_load_from_the_package() -> None:
    gates = load_gates()
    assert gates and {g["suite"] for g in gates} >= {"quick", "paper", "hard"}
    assert all("metric" in g for g in gates)


def test_an_installed_wheel_finds_its_gates_away_from_the_source_tree(tmp_path: Path) -> None:
    """Build a wheel from a copy of the sources, unpack it elsewhere, and load the gates from there alone."""
    source = tmp_path / "src"
    packages = [p.parent.name for p in ROOT.glob("*/__init__.py")]
    for name in packages:
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "--no-build-isolation",
                            "-q", "-w", str(tmp_path / "wheel")], capture_output=True, text=True, timeout=300,
                           check=False)
    assert build.returncode == 0, build.stderr
    (wheel,) = (tmp_path / "wheel").glob("frictionbench-*.whl")
    installed = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        z.extractall(installed)
    # one import name: the wheel's only top-level package is frictionbench, holding every package of the checkout
    assert {n.split("/")[0] for n in names if ".dist-info/" not in n} == {"frictionbench"}
    assert "frictionbench/bench/gates.toml" in names
    assert "frictionbench/bench/matrices/presets.toml" in names and "frictionbench/bench/matrices/paper.toml" in names
    checkout_packages = {p.parent.relative_to(ROOT).as_posix() for name in packages
                         for p in (ROOT / name).rglob("__init__.py")} - {"frictionbench"}
    assert {f"frictionbench/{p}/__init__.py" for p in checkout_packages} <= set(names)
    code = ("import frictionbench.bench.gates as g, frictionbench.bench.matrix as m, pathlib; gates = g.load_gates(); "
            "print(len(gates), len(m.variant_set('paper')), pathlib.Path(g.__file__).resolve().parent)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"PYTHONPATH": str(installed)}
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    count, paper, where = done.stdout.split()
    assert int(count) == len(load_gates()) and int(paper) == len(variant_set("paper"))  # the variant sets ship too
    assert Path(where) == (installed / "frictionbench" / "bench").resolve()  # the unpacked copy, not this checkout
