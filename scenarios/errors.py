"""Errors raised for bad input: each names the field (or file) and the offending value."""

from __future__ import annotations

import json
import re

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def key_path(field: str, key: object) -> str:
    """`field.key` as TOML writes it: a key that is not a bare key (empty, spaces, dots, ...) is quoted."""
    text = str(key)
    name = text if _BARE_KEY.fullmatch(text) else json.dumps(text)
    return f"{field}.{name}" if field else name


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
