"""The version of the physics and numerics that a trajectory depends on.

PHYSICS_VERSION names what a run computes beyond its settings (the scenario, the solver and its parameters, the
mesh, all in its store key `bench.store.run_key`): the continuum model, the contact and friction laws, the
integrators, Newton's iteration and tolerances, the linear solvers' use. The truth store (`bench.store.TruthStore`)
keys its runs by it, so that a truth computed by other physics is never reused.

Bump it (by one) with any change that moves a trajectory, even at round-off, and regenerate the guard's fixture:
`python tests/test_physics_version.py --regenerate` (tests/data/physics_guard.json; the guard test fails, naming
this constant, when the guarded run moves and the version did not change).
"""

from __future__ import annotations

#: Bump on any change that moves a trajectory (see the module docstring).
PHYSICS_VERSION: int = 3
# 2: the fixed-point contact lag's damping gate is monotone within a step and each re-lag takes one Newton
#    iteration (solvers.step.ContactLag); fixed-point runs move, start-lag runs do not.
# 3: modified Newton's contraction test starts afresh at each re-lag of the fixed-point contact lag
#    (solvers.full.solver._LaggedStep.relag); runs with chord_contraction and the fixed point move, others do not.
