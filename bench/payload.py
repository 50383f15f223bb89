"""What a matrix task carries to a worker and what it brings back: nothing is read or written through paths.

A worker may share no filesystem with the client (a Dask cluster on Kubernetes, a cloud or an HPC allocation), so
a task carries the mesh arrays and, for a reduced variant, the files its parameters name (a trained checkpoint, a
basis, a cubature) as bytes; it returns the trajectory (with a reduced run's basis) and the stats, and the client writes the
store. Meshes and artefacts are shared once per worker by the executor (`share`), not copied into every task.

An artefact is the folder of a file parameter (the prepare hook's output folder under `OUT/models/<key>/`, whose
other files a plug-in may read, e.g. POD's `info.json`), identified by a digest of its contents. A worker writes it
once into its own cache, `cache_root()/artefacts/<digest>/`, and runs with the parameters pointing there.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path


from frictionbench.solvers.trajectory import Trajectory


@dataclass(frozen=True)
class Artefact:
    """A folder of files carried to workers as bytes.

    source: the folder as the client's parameters name it (relative or absolute, as given).
    files: (name, content) of every plain file in it, sorted by name (sub-folders are not carried).
    digest: sha256 of names and contents, 16 hex digits: where a worker keeps its copy.
    """

    source: str
    files: tuple[tuple[str, bytes], ...]
    digest: str

    @classmethod
    def of(cls, folder: str | os.PathLike) -> Artefact:
        """Read `folder`'s plain files."""
        files = tuple((p.name, p.read_bytes()) for p in sorted(Path(folder).iterdir()) if p.is_file()
                      and not p.name.startswith("."))  # not the temporary files of an atomic write
        h = hashlib.sha256()
        for name, data in files:
            h.update(name.encode() + b"\0" + len(data).to_bytes(8, "little") + data)
        return cls(source=str(folder), files=files, digest=h.hexdigest()[:16])

    def materialise(self, root: Path) -> Path:
        """This artefact's folder under `root` (`root/<digest>`), written first if absent; a folder is renamed
        into place whole, so a concurrent or interrupted writer never leaves a partial copy behind."""
        folder = root / self.digest
        if folder.is_dir():
            return folder
        root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".{self.digest}."))
        try:
            for name, data in self.files:
                (tmp / name).write_bytes(data)
            os.rename(tmp, folder)
        except OSError:
            if not folder.is_dir():  # not merely another process that got there first
                raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return folder


def file_params(params: dict) -> dict[str, Path]:
    """The parameters that name an existing file by a path with a folder part (what a prepare hook returns:
    `checkpoint`, `basis`, ...; plain settings such as `"all"` or `"optimized:60"` have none)."""
    return {k: Path(v) for k, v in params.items()
            if isinstance(v, str) and os.sep in v and Path(v).is_file()}


def artefact_folders(params: dict) -> list[str]:
    """The distinct folders of `params`' file parameters (see `file_params`), as the parameters name them."""
    return sorted({str(p.parent) for p in file_params(params).values()})


def localised(params: dict, artefacts: tuple[Artefact, ...], root: Path) -> dict:
    """`params` with every file parameter inside a carried artefact pointing at the worker's copy under `root`."""
    by_source = {a.source: a for a in artefacts}
    out = dict(params)
    for k, path in ((k, Path(v)) for k, v in params.items() if isinstance(v, str) and os.sep in v):
        artefact = by_source.get(str(path.parent))
        if artefact is not None:
            out[k] = str(artefact.materialise(root) / path.name)
    return out


@dataclass(frozen=True)
class RunResult:
    """What one task returns to the client, which stores it.

    trajectory: the frames (None if the run failed before producing any).
    stats: JSON-serialisable run statistics (`failed`, `failure`, timings, solver health).
    """

    trajectory: Trajectory | None
    stats: dict
