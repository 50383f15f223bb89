"""frictionbench: full-space FEM against reduced-order simulation of deformable solids with frictional contact.

The distribution installs this one top-level package; its subpackages (`frictionbench.scenarios`,
`frictionbench.solvers`, `frictionbench.analysis`, `frictionbench.reports`, `frictionbench.bench`) are the
repository's top-level folders, mapped by `package-dir` in pyproject.toml. In a source checkout (the folders beside
this one) they are found through the repository root, so that the checkout runs with `PYTHONPATH=<checkout>` as well
as installed.
"""

import os
from pathlib import Path

#: MKL's conditional numerical reproducibility, set before any MKL loads in this process, whichever loads it first
#: (PARDISO in `solvers.linalg`, torch's MKL when a reduced model trains; a user's MKL_CBWR wins): without it, a
#: process started with MKL_NUM_THREADS=1 (as Dask's worker nanny starts them) takes another code path than one
#: limited to a thread at run time (threadpoolctl, the process pool), and their trajectories differ in the last bits
#: (measured: 2.8e-16 m after 40 steps of quick/p1_mu0.1), which a reduced model trained on them amplifies; and a
#: reduced model trained before PARDISO was first loaded would train in another mode than one trained after.
os.environ.setdefault("MKL_CBWR", "AUTO,STRICT")

_checkout = Path(__file__).resolve().parent.parent
if (_checkout / "pyproject.toml").is_file() and (_checkout / "bench" / "__init__.py").is_file():
    __path__.append(str(_checkout))
