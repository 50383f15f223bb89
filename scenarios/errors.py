"""Errors raised for bad input: each names the field (or file) and the offending value."""

from __future__ import annotations


class ScenarioError(ValueError):
    """A scenario, suite or mesh input is invalid.

    field: dotted path of the offending field (e.g. `material.poisson_ratio`) or a file path.
    value: the offending value (repr'd in the message).
    """

    def __init__(self, field: str, value: object, reason: str) -> None:
        self.field = field
        self.value = value
        self.reason = reason
        super().__init__(f"{field} = {value!r}: {reason}")


class MeshError(ScenarioError):
    """A mesh file or catalogue entry is invalid (unknown, unreadable, inverted, non-manifold, ...)."""
