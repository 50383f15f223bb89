"""Atomic writes (scenarios.atomic): a reader sees the old file or the complete new one."""

from __future__ import annotations

import json
import stat

import pytest

from frictionbench.scenarios.atomic import atomic_open, write_json_atomic, write_text_atomic


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path) -> None:
    path = write_text_atomic(tmp_path / "sub" / "a.txt", "old")
    with pytest.raises(RuntimeError, match="midway"):
        with atomic_open(path, "w") as f:
            f.write("new, half written")
            raise RuntimeError("midway")
    assert path.read_text() == "old"
    assert [p.name for p in path.parent.iterdir()] == ["a.txt"]


def test_writes_replace_the_file_readable_by_all(tmp_path) -> None:
    path = write_json_atomic(tmp_path / "s.json", {"b": 1, "a": float("inf"), "p": tmp_path})
    assert json.loads(path.read_text()) == {"a": float("inf"), "b": 1, "p": str(tmp_path)}
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    with atomic_open(path, "wb") as f:
        f.write(b"\x00bytes")
    assert path.read_bytes() == b"\x00bytes"
    with pytest.raises(ValueError, match="mode 'a'"):
        with atomic_open(path, "a"):
            pass
