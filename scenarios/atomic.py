"""Atomic file writes, used by every layer: a reader sees the old file or the complete new one, never a part.

The content is written to a temporary file in the target's folder, which is then renamed onto the target
(`os.replace`, atomic on POSIX and Windows within one file system). A write that fails removes its temporary
file and leaves the target as it was.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

#: Permissions of a written file (mkstemp would leave 0600): readable by everyone, writable by the owner.
FILE_MODE = 0o644


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w") -> Iterator[IO]:
    """Open a temporary file beside `path` for writing (`mode` "w" for UTF-8 text, "wb" for bytes); when the
    block ends without an exception, rename it onto `path`. Creates the parent folder."""
    if mode not in ("w", "wb"):
        raise ValueError(f"mode {mode!r}: expected 'w' or 'wb'")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with (os.fdopen(fd, "wb") if mode == "wb" else os.fdopen(fd, "w", encoding="utf-8", newline="")) as f:
            yield f
        os.chmod(tmp, FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write `text` (UTF-8, newlines as given) to `path` atomically; returns the path."""
    with atomic_open(path, "w") as f:
        f.write(text)
    return Path(path)


def write_json_atomic(path: str | os.PathLike, obj: object) -> Path:
    """Write `obj` as indented JSON with sorted keys to `path` atomically (values JSON cannot hold are written
    as their str()); returns the path."""
    with atomic_open(path, "w") as f:
        json.dump(obj, f, indent=2, sort_keys=True, default=str)
    return Path(path)
