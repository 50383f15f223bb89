"""The layers point one way: scenarios <- solvers <- analysis <- reports <- bench (import-linter contracts in
pyproject.toml). A package that imports one above it breaks the build here, not by convention.

The checkout maps the subpackages of `frictionbench` from its top-level folders (pyproject's package-dir), while
import-linter reads a package from its own folder: the contracts run on a copy of the sources laid out as installed
(`lint`)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = ("from importlinter.cli import lint_imports; "
        "raise SystemExit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")


def subpackages(folder: Path = ROOT) -> list[str]:
    """The subpackages of `frictionbench` in a checkout: its top-level folders with an __init__.py."""
    return sorted(p.parent.name for p in folder.glob("*/__init__.py") if p.parent.name != "frictionbench")


def lint(checkout: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    """Run the contracts of `checkout`/pyproject.toml on the checkout's sources, copied into
    tmp_path/installed/frictionbench/<subpackage> (they come first on the path)."""
    installed = tmp_path / "installed"
    shutil.copytree(checkout / "frictionbench", installed / "frictionbench")
    for name in subpackages(checkout):
        shutil.copytree(checkout / name, installed / "frictionbench" / name,
                        ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(checkout / "pyproject.toml", installed / "pyproject.toml")
    env = os.environ | {"PYTHONPATH": str(installed)}
    return subprocess.run([sys.executable, "-c", LINT], cwd=installed, env=env, capture_output=True, text=True,
                          timeout=300, check=False)


def contracts() -> dict:
    """The import-linter section of pyproject.toml."""
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["importlinter"]


def test_the_layer_contracts_are_kept(tmp_path: Path) -> None:
    done = lint(ROOT, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 broken" in done.stdout


def test_every_package_of_the_project_is_in_the_layers() -> None:
    """A new top-level package outside the layers would escape the contract; the one import name is the root."""
    config = contracts()
    layered = {name.strip() for layer in config["contracts"][0]["layers"] for name in layer.split("|")}
    assert config["root_packages"] == ["frictionbench"] == config["contracts"][0]["containers"]
    assert set(subpackages()) == layered


def layout(folder: Path) -> None:
    """An empty copy of the checkout's layout in `folder`: pyproject.toml, frictionbench/, every subpackage folder
    and every module the contracts name (a package where the project has one), `frictionbench.X.Y` at X/Y."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text(encoding="utf-8"), encoding="utf-8")
    modules = {f"frictionbench.{name}" for name in subpackages()}
    for contract in contracts()["contracts"]:
        for container in contract.get("containers", []):
            modules |= {f"{container}.{name.strip()}" for layer in contract["layers"] for name in layer.split("|")}
        modules |= set(contract.get("source_modules", [])) | set(contract.get("forbidden_modules", []))
    (folder / "frictionbench").mkdir()
    (folder / "frictionbench" / "__init__.py").write_text("")
    for module in sorted(modules):
        parts = module.split(".")[1:]
        path = folder.joinpath(*parts)
        if ROOT.joinpath(*parts).is_dir():
            path.mkdir(parents=True, exist_ok=True)
            (path / "__init__.py").write_text("")
        else:
            path.with_suffix(".py").write_text("")


def test_an_import_against_the_layers_is_a_failure(tmp_path: Path) -> None:
    """The same contracts on a copy of the layout where analysis imports bench: lint fails and names the import."""
    checkout = tmp_path / "checkout"
    layout(checkout)
    (checkout / "analysis" / "metrics.py").write_text("import frictionbench.bench.runner\n")
    done = lint(checkout, tmp_path)
    assert done.returncode != 0
    assert "frictionbench.analysis.metrics -> frictionbench.bench.runner" in done.stdout


@pytest.mark.parametrize("backend", ["frictionbench.solvers.full.solver", "frictionbench.solvers.reduced.solver",
                                     "frictionbench.solvers.build"])
def test_physics_that_imports_a_backend_or_the_model_builder_is_a_failure(tmp_path: Path, backend: str) -> None:
    """A physics term that names a backend (even only for type checking) or imports the model builder (the old
    import circle solvers.build -> physics -> solvers.build) breaks the contracts."""
    checkout = tmp_path / "checkout"
    layout(checkout)
    (checkout / "solvers" / "physics" / "terms.py").write_text(
        f"from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import {backend}\n")
    for module in (backend, "frictionbench.solvers.build"):
        checkout.joinpath(*module.split(".")[1:]).with_suffix(".py").write_text(
            "import frictionbench.solvers.physics.terms\n")
    done = lint(checkout, tmp_path)
    assert done.returncode != 0
    assert f"frictionbench.solvers.physics.terms -> {backend}" in done.stdout
