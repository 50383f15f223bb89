"""The layers point one way: scenarios <- solvers <- analysis <- reports <- bench (import-linter contracts in
pyproject.toml). A package that imports one above it breaks the build here, not by convention."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = ("from importlinter.cli import lint_imports; "
        "raise SystemExit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")


def lint(folder: Path) -> subprocess.CompletedProcess:
    """Run the contracts of `folder`/pyproject.toml on the packages in `folder` (they come first on the path)."""
    env = os.environ | {"PYTHONPATH": str(folder)}
    return subprocess.run([sys.executable, "-c", LINT], cwd=folder, env=env, capture_output=True, text=True,
                          timeout=300, check=False)


def contracts() -> dict:
    """The import-linter section of pyproject.toml."""
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["importlinter"]


def test_the_layer_contracts_are_kept() -> None:
    done = lint(ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 broken" in done.stdout


def test_every_package_of_the_project_is_in_the_layers() -> None:
    """A new top-level package outside the layers would escape the contract."""
    packages = {p.parent.name for p in ROOT.glob("*/__init__.py")}
    config = contracts()
    layered = {name.strip() for layer in config["contracts"][0]["layers"] for name in layer.split("|")}
    assert packages == set(config["root_packages"]) == layered


def test_an_import_against_the_layers_is_a_failure(tmp_path: Path) -> None:
    """The same contracts on a copy of the layout where analysis imports bench: lint fails and names the import."""
    (tmp_path / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text(encoding="utf-8"), encoding="utf-8")
    for package in contracts()["root_packages"]:
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("")
    inner = next(c for c in contracts()["contracts"] if c.get("containers") == ["bench"])
    for module in {name.strip() for layer in inner["layers"] for name in layer.split("|")}:
        (tmp_path / "bench" / f"{module}.py").write_text("")
    (tmp_path / "analysis" / "metrics.py").write_text("import bench.runner\n")
    done = lint(tmp_path)
    assert done.returncode != 0
    assert "analysis.metrics -> bench.runner" in done.stdout
