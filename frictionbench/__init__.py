"""frictionbench: full-space FEM against reduced-order simulation of deformable solids with frictional contact.

The distribution installs this one top-level package; its subpackages (`frictionbench.scenarios`,
`frictionbench.solvers`, `frictionbench.analysis`, `frictionbench.reports`, `frictionbench.bench`) are the
repository's top-level folders, mapped by `package-dir` in pyproject.toml. In a source checkout (the folders beside
this one) they are found through the repository root, so that the checkout runs with `PYTHONPATH=<checkout>` as well
as installed.

Importing the package registers the built-in time integrators (`solvers.integrators`) with the scenario loader,
which validates `time.integrator` against their names: the loader sits in the bottom layer and may not import
solvers, while any import of a subpackage imports this package first.
"""

from pathlib import Path

_checkout = Path(__file__).resolve().parent.parent
if (_checkout / "pyproject.toml").is_file() and (_checkout / "bench" / "__init__.py").is_file():
    __path__.append(str(_checkout))

import frictionbench.solvers.integrators  # noqa: E402,F401  (after __path__: in a checkout it is found there)
