"""Solvers: HOW a scenario is simulated. One interface (Model / State / step), many solvers."""
