"""Errors raised for bad input: each names the field (or file) and the offending value."""

from __future__ import annotations

import difflib
import json
import re
from collections.abc import Mapping, Sequence
from typing import Any

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


def checked_table(value: object, field: str, allowed: Sequence[str] | None, top: str) -> Mapping[str, Any]:
    """`value` as a TOML table, raising `ScenarioError` otherwise.

    field: its dotted path ("" for the document itself, then named `top` in the error, e.g. "<suite>").
    allowed: the keys it may have (None: any); an unknown key is named, with the closest allowed key as a hint.
    """
    if not isinstance(value, Mapping):
        raise ScenarioError(field or top, value, "expected a table")
    for key in value:
        if allowed is not None and key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ScenarioError(key_path(field, key), value[key],
                                f"unknown key{hint} (expected one of {list(allowed)})")
    return value


class MeshError(ScenarioError):
    """A mesh file or catalogue entry is invalid (unknown, unreadable, inverted, non-manifold, ...)."""
