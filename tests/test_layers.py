"""The layers point one way: scenarios <- solvers <- analysis <- reports <- bench (import-linter contracts in
pyproject.toml). A package that imports one above it breaks the build here, not by convention."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

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


def layout(folder: Path) -> None:
    """An empty copy of the project's layout in `folder`: pyproject.toml, every root package and every module the
    contracts name (a package where the project has one)."""
    (folder / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text(encoding="utf-8"), encoding="utf-8")
    modules = set(contracts()["root_packages"])
    for contract in contracts()["contracts"]:
        for container in contract.get("containers", []):
            modules |= {f"{container}.{name.strip()}" for layer in contract["layers"] for name in layer.split("|")}
        modules |= set(contract.get("source_modules", [])) | set(contract.get("forbidden_modules", []))
    for module in sorted(modules):
        path = folder.joinpath(*module.split("."))
        if ROOT.joinpath(*module.split(".")).is_dir():
            path.mkdir(parents=True, exist_ok=True)
            (path / "__init__.py").write_text("")
        else:
            path.with_suffix(".py").write_text("")


def test_an_import_against_the_layers_is_a_failure(tmp_path: Path) -> None:
    """The same contracts on a copy of the layout where analysis imports bench: lint fails and names the import."""
    layout(tmp_path)
    (tmp_path / "analysis" / "metrics.py").write_text("import bench.runner\n")
    done = lint(tmp_path)
    assert done.returncode != 0
    assert "analysis.metrics -> bench.runner" in done.stdout


@pytest.mark.parametrize("backend", ["solvers.full.solver", "solvers.licrom.reduced", "solvers.model"])
def test_physics_that_imports_a_backend_or_the_model_builder_is_a_failure(tmp_path: Path, backend: str) -> None:
    """A physics term that names a backend (even only for type checking) or imports the model builder (the old
    import circle solvers.model -> physics -> solvers.model) breaks the contracts."""
    layout(tmp_path)
    (tmp_path / "solvers" / "physics" / "terms.py").write_text(
        f"from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import {backend}\n")
    for module in (backend, "solvers.model"):
        tmp_path.joinpath(*module.split(".")).with_suffix(".py").write_text("import solvers.physics.terms\n")
    done = lint(tmp_path)
    assert done.returncode != 0
    assert f"solvers.physics.terms -> {backend}" in done.stdout
