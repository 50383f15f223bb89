"""Sparse symmetric positive-definite direct solvers for Newton's method on a fixed 3x3-block sparsity pattern.

A factoriser is made once per mesh (pattern), factorises each Newton iteration's matrix and solves with it:

- `PardisoFactoriser`: MKL PARDISO (through pypardiso) in real-SPD mode (mtype 2) on the upper triangle in CSR.
  Its symbolic analysis (METIS ordering, elimination tree) runs once, at the first factorisation; each later
  iteration runs only the numeric Cholesky factorisation (phase 22) and the solve (phase 33). The matrix values
  are gathered from the block values by one precomputed index map, with no format conversion. MKL's thread count
  follows the caller's thread-pool limits (`threadpoolctl.threadpool_limits`, MKL_NUM_THREADS).
- `SuperLUFactoriser`: SciPy's SuperLU in symmetric mode, a fresh ordering and LU factorisation per matrix (the
  solver's original path, and the fallback where MKL is not installed or does not load).

`make_factoriser(kind, ...)` picks one by name: `pardiso`, `superlu`, or `direct` (PARDISO where it loads, else
SuperLU). `PARDISO_ERROR` says why PARDISO is unavailable ('' where it loads).

`negative_eigenvalues` counts the negative eigenvalues of a sparse symmetric matrix exactly (Sylvester's law of
inertia on an LDL^T factorisation: PARDISO's symmetric-indefinite mode, else a dense LDL^T).
"""

from __future__ import annotations

import functools
import os
import weakref
from typing import Protocol

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # loading pypardiso loads MKL's runtime (mkl_rt), so thread-pool limits entered later apply to it
    import pypardiso

    if not hasattr(pypardiso.PyPardisoSolver, "_call_pardiso"):  # the phase-level call used below (pypardiso 0.4)
        raise ImportError(f"pypardiso {pypardiso.__version__} has no PyPardisoSolver._call_pardiso")
    # Every PyPardisoSolver looks for mkl_rt again, by a recursive glob over the environment's lib tree (1.5 s a solver
    # in a venv with torch) unless PYPARDISO_MKL_RT names it: name the library its module-level solver loaded (where
    # this pypardiso has one; otherwise the search stays, slower but correct).
    _loaded = getattr(getattr(getattr(pypardiso, "ps", None), "libmkl", None), "_name", None)
    if _loaded:
        os.environ.setdefault("PYPARDISO_MKL_RT", _loaded)
    PARDISO_ERROR = ""
except (ImportError, OSError) as err:  # not installed (non-x86 platforms), or mkl_rt missing / not loadable
    pypardiso = None
    PARDISO_ERROR = f"{type(err).__name__}: {err}"

#: PARDISO matrix type: real symmetric positive definite (Cholesky, no pivoting).
MTYPE_REAL_SPD = 2
#: PARDISO matrix type: real symmetric indefinite (LDL^T with Bunch-Kaufman pivoting).
MTYPE_REAL_SYMMETRIC_INDEFINITE = -2
#: PARDISO's iparm (0-based index: value) set here; every other entry is 0. 0: use these values, not PARDISO's
#: defaults; 1: nested-dissection ordering (METIS); 7: iterative refinement only where pivots were perturbed, never
#: in a Cholesky factorisation (the defaults do 2 steps a solve, which quadruples the solve time and changes nothing
#: measurable on these SPD matrices: residuals ~1e-14 either way); 9: pivot perturbation 1e-8 (PARDISO's value for
#: symmetric matrices, unused without pivoting); 17: report the nonzeros of the factor in iparm[17].
PARDISO_IPARM = {0: 1, 1: 2, 7: 0, 9: 8, 17: -1}
#: Names `make_factoriser` accepts.
DIRECT_SOLVERS = ("direct", "pardiso", "superlu")


def superlu_spd(H: sp.csc_matrix) -> spla.SuperLU:
    """SuperLU factorisation of a sparse symmetric positive-definite H in symmetric mode (minimum-degree ordering
    on H + H^T, diagonal pivoting): measured fastest of SuperLU's orderings on these meshes."""
    return spla.splu(H, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


def sparse_spd_solve(H: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
    """Solve H x = b for a sparse symmetric positive-definite H (SuperLU, `superlu_spd`)."""
    return superlu_spd(H).solve(b)


class Factoriser(Protocol):
    """Factorise a block-sparse SPD matrix given its block values, then solve with it."""

    name: str

    def factorize(self, values: np.ndarray) -> None:
        """Factorise the matrix whose 3x3 blocks, in the pattern's order, are `values` (nnzb, 3, 3)."""

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x (3n,) with H x = b (3n,) for the last factorised H."""


class SuperLUFactoriser:
    """SciPy SuperLU (symmetric mode) on the full matrix, converted from the blocks each time (BSR to CSC)."""

    name = "superlu"

    def __init__(self, offsets: np.ndarray, cols: np.ndarray, n: int) -> None:
        self.offsets, self.cols, self.n = offsets, cols, n
        self._lu: spla.SuperLU | None = None

    def factorize(self, values: np.ndarray) -> None:
        """Fresh minimum-degree ordering and LU factorisation of the (3n, 3n) matrix with blocks `values`."""
        H = sp.bsr_matrix((values, self.cols, self.offsets), shape=(3 * self.n, 3 * self.n)).tocsc()
        self._lu = None  # until this factorisation succeeds
        self._lu = superlu_spd(H)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x = H^-1 b with the last factorisation."""
        if self._lu is None:
            raise RuntimeError("solve called before factorize")
        return self._lu.solve(b)


class UpperCSR:
    """The upper triangle of a 3x3-block matrix (block CSR `offsets` (n+1,), `cols` (nnzb,), sorted per row) as
    scalar CSR, and the map from the block values to its data: data = values.reshape(-1)[gather].

    indptr: (3n+1,), indices: (nnz,) column of each entry, sorted within each row; gather: (nnz,) int64.
    """

    def __init__(self, offsets: np.ndarray, cols: np.ndarray, n: int) -> None:
        block_row = np.repeat(np.arange(n), np.diff(offsets))
        b_idx = np.arange(cols.size)
        keep = cols >= block_row  # blocks on or above the diagonal
        b_idx, brow, bcol = b_idx[keep], block_row[keep], cols[keep].astype(np.int64)
        # every (block, r, c) entry, ordered row-major over scalar rows: by block row, then r, then block, then c
        r = np.arange(3)
        blk = np.broadcast_to(b_idx[None, :, None], (3, b_idx.size, 3))
        rr = np.broadcast_to(r[:, None, None], blk.shape)
        cc = np.broadcast_to(r[None, None, :], blk.shape)
        row = 3 * brow[None, :, None] + rr
        col = 3 * bcol[None, :, None] + cc
        order = np.lexsort((col.ravel(), row.ravel()))
        row, col = row.ravel()[order], col.ravel()[order]
        blk, rr, cc = blk.ravel()[order], rr.ravel()[order], cc.ravel()[order]
        upper = col >= row  # within diagonal blocks, only r <= c
        self.gather = (9 * blk + 3 * rr + cc)[upper].astype(np.int64)
        self.indices = col[upper].astype(np.int32)
        self.indptr = np.searchsorted(row[upper], np.arange(3 * n + 1)).astype(np.int32)
        self.shape = (3 * n, 3 * n)

    def matrix(self, values: np.ndarray) -> sp.csr_matrix:
        """The upper triangle as a new CSR matrix with block values `values` (nnzb, 3, 3)."""
        return sp.csr_matrix((np.ascontiguousarray(values).reshape(-1)[self.gather], self.indices, self.indptr),
                             shape=self.shape)


class PardisoFactoriser:
    """MKL PARDISO, real SPD (Cholesky), analysis once per pattern, numeric factorisation per matrix."""

    name = "pardiso"

    def __init__(self, offsets: np.ndarray, cols: np.ndarray, n: int) -> None:
        if pypardiso is None:
            raise RuntimeError(f"PARDISO is unavailable ({PARDISO_ERROR}); install pypardiso (x86-64)")
        self.upper = UpperCSR(offsets, cols, n)
        self.H = self.upper.matrix(np.zeros((cols.size, 3, 3)))
        self._pardiso = pypardiso.PyPardisoSolver(mtype=MTYPE_REAL_SPD)
        for i, value in PARDISO_IPARM.items():
            self._pardiso.iparm[i] = value
        self._analysed = self._factorised = False
        weakref.finalize(self, self._pardiso.free_memory, True)  # PARDISO's memory is outside Python's heap

    def _phase(self, phase: int, b: np.ndarray) -> np.ndarray:
        """Run PARDISO phase `phase` (11 analysis, 22 numeric factorisation, 33 solve) on self.H with right-hand
        side b (3n, 1); an error names the phase (-4 in factorisation: the matrix is not positive definite)."""
        self._pardiso.set_phase(phase)
        try:
            return self._pardiso._call_pardiso(self.H, b)  # noqa: SLF001 (pypardiso's phase-level entry point)
        except pypardiso.pardiso_wrapper.PyPardisoError as err:
            raise RuntimeError(f"PARDISO phase {phase} on the ({self.H.shape[0]} x {self.H.shape[0]}) Newton "
                               f"matrix failed with error {err.value} (-4: not positive definite)") from err

    @property
    def factor_nnz(self) -> int:
        """Nonzeros of the Cholesky factor (0 before the analysis)."""
        return int(self._pardiso.iparm[17]) if self._analysed else 0

    def factorize(self, values: np.ndarray) -> None:
        """Gather the upper-triangle values, run the symbolic analysis if not done yet, factorise (LL^T)."""
        np.take(np.ascontiguousarray(values).reshape(-1), self.upper.gather, out=self.H.data)
        dummy = np.zeros((self.H.shape[0], 1))
        if not self._analysed:
            self._phase(11, dummy)
            self._analysed = True
        self._factorised = False  # until this factorisation succeeds: never solve with a stale factor
        self._phase(22, dummy)
        self._factorised = True

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x = H^-1 b with the last factorisation."""
        if not self._factorised:
            raise RuntimeError("solve called before factorize")
        return self._phase(33, np.asfortranarray(b, dtype=np.float64).reshape(-1, 1)).reshape(b.shape)


def make_factoriser(kind: str, offsets: np.ndarray, cols: np.ndarray, n: int) -> Factoriser:
    """The direct solver `kind` (`direct`: PARDISO where it loads, else SuperLU) for the block pattern
    (`offsets` (n+1,), `cols` (nnzb,)) of an (3n, 3n) SPD matrix."""
    if kind not in DIRECT_SOLVERS:
        raise ValueError(f"solver.linear = {kind!r}: expected one of {DIRECT_SOLVERS}")
    if kind == "pardiso" and pypardiso is None:
        raise ValueError(f"solver.linear = 'pardiso': PARDISO is unavailable here ({PARDISO_ERROR}); "
                         "use 'superlu' or 'auto'")
    if kind == "superlu" or (kind == "direct" and pypardiso is None):
        return SuperLUFactoriser(offsets, cols, n)
    return PardisoFactoriser(offsets, cols, n)


@functools.cache
def _indefinite_solver() -> "pypardiso.PyPardisoSolver":
    """One PARDISO instance in real-symmetric-indefinite mode, made once (making one searches the file system for
    MKL's library: seconds), its memory released after each use."""
    return pypardiso.PyPardisoSolver(mtype=MTYPE_REAL_SYMMETRIC_INDEFINITE)


def negative_eigenvalues(A: sp.spmatrix) -> int:
    """The number of negative eigenvalues of the sparse symmetric matrix A (N, N), exactly: by Sylvester's law of
    inertia, the negative pivots of A = L D L^T. PARDISO (real symmetric indefinite, its defaults) reports them in
    iparm[22] after the factorisation; a pivot it had to perturb (iparm[13] > 0, A singular to working precision)
    would make the count unreliable, and is an error. Without PARDISO, a dense LDL^T (`scipy.linalg.ldl`; D's
    1x1 and 2x2 blocks make a symmetric tridiagonal matrix with the same inertia), O(N^3)."""
    if pypardiso is None:
        _, D, _ = sla.ldl(A.toarray())
        return int(np.count_nonzero(sla.eigvalsh_tridiagonal(np.diag(D).copy(), np.diag(D, 1).copy()) < 0.0))
    upper = sp.triu(A, format="csr")
    upper.sort_indices()
    solver = _indefinite_solver()
    try:
        solver.set_phase(12)  # analysis and numeric factorisation
        solver._call_pardiso(upper, np.zeros((A.shape[0], 1)))  # noqa: SLF001 (pypardiso's phase-level entry)
        negative, perturbed = int(solver.iparm[22]), int(solver.iparm[13])
    finally:
        solver.free_memory(everything=True)
    if perturbed:
        raise RuntimeError(f"PARDISO perturbed {perturbed} pivots of the ({A.shape[0]} x {A.shape[0]}) matrix: it "
                           "is singular to working precision, so its inertia is not reliable")
    return negative
