"""Readers for the Siconos test-problem files (LCP and 2D frictional contact).

The files come from Siconos's test suite (``numerics/src/LCP/test/data/`` and
``numerics/src/FrictionContact/test/data/``); the project's copy, with its licence, is test
data in ``tests/data/siconos/``.  Format notes (from Siconos's
``NM_write_in_file`` / ``SBM_write_in_file`` / CSparse's ``cs_print``):

* Dense matrices (storage kind 0): ``size0``, ``size1``, a line ``size0<TAB>size1`` and then
  the ``size0 * size1`` entries in **column-major** order (Siconos stores dense matrices the
  Fortran way).  The numbers are laid out one text line per *column*, so a file line is a
  column of the matrix, not a row.  (Checked against Cottle-Pang-Stone example 4.4.7, the
  source of ``lcp_CPS_2``, and against the sparse-block copies of the same problems.)
* Sparse-block matrices (kind 1): number of blocks, number of block rows / columns, the
  cumulative block sizes, the CSR-like block index arrays, then per block its number and its
  entries (column-major).  Supported by `read_lcp`.
* CSparse dumps (kind 2): the sparse origin code (2 = compressed columns), then CSparse's
  human-readable ``cs_print`` listing (``col j : locations a to b`` / ``i : x``).  Supported
  for compressed-column dumps; note that ``cs_print`` writes the values with ``%g``, i.e.
  rounded to 6 significant digits, so such a W is only approximately symmetric.

LCP file: ``n``, then the matrix (storage kind, sizes, entries), then ``q`` (n numbers);
anything after q is a comment.  fc2d file: the dimension (2), the number of contacts nc, the
matrix W (2nc x 2nc; per contact the normal then the tangential row), q (2nc), mu (nc).

Errors (unsupported storage, truncated or inconsistent files) raise ValueError naming the
file; a missing file raises FileNotFoundError.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

__all__ = [
    "read_fc2d",
    "read_lcp",
]

STORAGE_DENSE = 0
STORAGE_SPARSE_BLOCK = 1
STORAGE_SPARSE = 2
#: Siconos's code for a compressed-column (CSC) sparse matrix in a kind-2 dump.
_NSM_CSC = 2


class _Tokens:
    """Whitespace-separated tokens of a text, consumed front to back."""

    def __init__(self, text: str, path) -> None:
        self.toks = text.split()
        self.pos = 0
        self.path = path

    def _next(self, what: str) -> str:
        if self.pos >= len(self.toks):
            raise ValueError(f"{self.path}: file ends before {what}")
        tok = self.toks[self.pos]
        self.pos += 1
        return tok

    def int(self, what: str) -> int:
        tok = self._next(what)
        try:
            val = float(tok)
        except ValueError:
            raise ValueError(f"{self.path}: expected an integer for {what}, got {tok!r}") from None
        if not val.is_integer():
            raise ValueError(f"{self.path}: expected an integer for {what}, got {tok!r}")
        return int(val)

    def floats(self, count: int, what: str) -> np.ndarray:
        if self.pos + count > len(self.toks):
            raise ValueError(f"{self.path}: file ends inside {what}")
        chunk = self.toks[self.pos : self.pos + count]
        self.pos += count
        try:
            return np.array([float(t) for t in chunk], dtype=np.float64)
        except ValueError:
            raise ValueError(f"{self.path}: non-numeric entry in {what}") from None


def _read_dense(tok: _Tokens, rows: int, cols: int) -> np.ndarray:
    r2, c2 = tok.int("the matrix row count"), tok.int("the matrix column count")
    if (r2, c2) != (rows, cols):
        raise ValueError(f"{tok.path}: matrix size lines disagree ({rows}x{cols} vs {r2}x{c2})")
    data = tok.floats(rows * cols, "the matrix entries")
    return data.reshape((rows, cols), order="F")


def _read_sparse_block(tok: _Tokens, rows: int, cols: int) -> np.ndarray:
    nblocks = tok.int("the number of blocks")
    nbr = tok.int("the number of block rows")
    nbc = tok.int("the number of block columns")
    bs0 = [tok.int("the block row sizes") for _ in range(nbr)]
    bs1 = [tok.int("the block column sizes") for _ in range(nbc)]
    filled1 = tok.int("filled1")
    filled2 = tok.int("filled2")
    index1 = [tok.int("the block row pointers") for _ in range(filled1)]
    index2 = [tok.int("the block column indices") for _ in range(filled2)]
    if (
        filled1 != nbr + 1
        or filled2 != nblocks
        or (bs0 and bs0[-1] != rows)
        or (bs1 and bs1[-1] != cols)
        or index1[0] != 0
        or index1[-1] != nblocks
    ):
        raise ValueError(f"{tok.path}: inconsistent sparse-block header")
    M = np.zeros((rows, cols))
    for i in range(nbr):
        r0 = bs0[i - 1] if i > 0 else 0
        nr = bs0[i] - r0
        for j in range(index1[i], index1[i + 1]):
            num = tok.int("a block number")
            if num != j:
                raise ValueError(f"{tok.path}: block {j} is numbered {num}")
            cb = index2[j]
            if not 0 <= cb < nbc:
                raise ValueError(f"{tok.path}: block column index {cb} out of range")
            c0 = bs1[cb - 1] if cb > 0 else 0
            nc = bs1[cb] - c0
            blk = tok.floats(nr * nc, f"block {j}")
            M[r0 : r0 + nr, c0 : c0 + nc] = blk.reshape((nr, nc), order="F")
    return M


_CS_HEADER = re.compile(r"^\s*(\S+)-by-(\S+),\s*nzmax:\s*(\S+)\s+nnz:\s*(\S+),\s*1-norm:\s*(\S+)")
_CS_COL = re.compile(r"^\s*col\s+(\S+)\s*:\s*locations\s+(\S+)\s+to\s+(\S+)\s*$")
_CS_ENTRY = re.compile(r"^\s*(\S+)\s*:\s*(\S+)\s*$")


def _read_csparse(text: str, start_line: int, rows: int, cols: int, path):
    """Parse a ``cs_print`` listing of a CSC matrix beginning at line ``start_line``.

    Returns (dense matrix, index of the first line after the listing)."""
    lines = text.splitlines()
    k = start_line
    if k < len(lines) and lines[k].lstrip().startswith("CSparse"):
        k += 1
    m = _CS_HEADER.match(lines[k]) if k < len(lines) else None
    if m is None:
        raise ValueError(f"{path}: expected a CSparse 'm-by-n, nzmax: .. nnz: ..' line")
    hr, hc, nnz = int(float(m.group(1))), int(float(m.group(2))), int(float(m.group(4)))
    norm1 = float(m.group(5))
    if (hr, hc) != (rows, cols):
        raise ValueError(f"{path}: CSparse header says {hr}x{hc}, expected {rows}x{cols}")
    k += 1
    M = np.zeros((rows, cols))
    col = -1
    expected_end = -1
    count = 0
    while k < len(lines):
        line = lines[k]
        mc = _CS_COL.match(line)
        if mc is not None:
            if col >= 0 and count != expected_end:
                raise ValueError(f"{path}: column {col} has fewer entries than announced")
            new_col = int(float(mc.group(1)))
            if new_col != col + 1:
                raise ValueError(f"{path}: CSparse column {new_col} follows column {col}")
            col = new_col
            a, b = int(float(mc.group(2))), int(float(mc.group(3)))
            if a != count:
                raise ValueError(f"{path}: column {col} starts at location {a}, expected {count}")
            expected_end = b + 1
            k += 1
            continue
        me = _CS_ENTRY.match(line)
        if me is not None and col >= 0:
            i = int(float(me.group(1)))
            if not 0 <= i < rows:
                raise ValueError(f"{path}: row index {i} out of range in column {col}")
            M[i, col] = float(me.group(2))
            count += 1
            if count > expected_end:
                raise ValueError(f"{path}: column {col} has more entries than announced")
            k += 1
            continue
        break
    if col != cols - 1 or count != nnz:
        raise ValueError(f"{path}: CSparse listing incomplete ({col + 1} of {cols} columns, {count} of {nnz} entries)")
    got = np.abs(M).sum(axis=0).max() if cols else 0.0
    if abs(got - norm1) > 1e-4 * max(1.0, abs(norm1)):
        raise ValueError(f"{path}: 1-norm {got:g} does not match the header's {norm1:g}")
    return M, k


def read_lcp(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a Siconos LCP file: returns (M, q) with M (n, n) and q (n,) float64.

    Supports dense storage (kind 0, entries in column-major order) and sparse-block
    storage (kind 1, the ``*_block.dat`` files; converted to a dense M).  Other storage kinds
    raise ValueError.  Trailing comments after q are ignored.
    """
    path = Path(path)
    text = path.read_text()
    tok = _Tokens(text, path)
    n = tok.int("the problem size n")
    kind = tok.int("the storage kind")
    rows, cols = tok.int("the row count"), tok.int("the column count")
    if (rows, cols) != (n, n):
        raise ValueError(f"{path}: matrix is {rows}x{cols}, expected {n}x{n}")
    if kind == STORAGE_DENSE:
        M = _read_dense(tok, n, n)
    elif kind == STORAGE_SPARSE_BLOCK:
        M = _read_sparse_block(tok, n, n)
    else:
        raise ValueError(f"{path}: storage kind {kind} not supported for LCP files")
    q = tok.floats(n, "q")
    return M, q


def read_fc2d(path, *, sparse: bool = False):
    """Read a Siconos 2D frictional contact file: returns (W, q, mu).

    W is (2nc, 2nc) (per contact: normal, then tangential), q (2nc,), mu (nc,), float64.
    Supports dense storage (kind 0) and CSparse dumps of compressed-column matrices (kind 2;
    values in those are rounded to 6 significant digits by Siconos's writer).  W is returned
    dense, or as a ``scipy.sparse.csc_matrix`` if ``sparse=True``.  Other storage kinds,
    dimension != 2 or inconsistent sizes raise ValueError.
    """
    path = Path(path)
    text = path.read_text()
    tok = _Tokens(text, path)
    dim = tok.int("the dimension")
    if dim != 2:
        raise ValueError(f"{path}: dimension {dim}, expected 2 for an fc2d problem")
    nc = tok.int("the number of contacts")
    kind = tok.int("the storage kind")
    rows, cols = tok.int("the row count"), tok.int("the column count")
    m = 2 * nc
    if (rows, cols) != (m, m):
        raise ValueError(f"{path}: W is {rows}x{cols}, expected {m}x{m}")
    if kind == STORAGE_DENSE:
        W = _read_dense(tok, m, m)
    elif kind == STORAGE_SPARSE:
        origin = tok.int("the sparse origin code")
        if origin != _NSM_CSC:
            raise ValueError(f"{path}: CSparse dump with origin code {origin} not supported (only compressed-column, code {_NSM_CSC})")
        # The dump is line-oriented: find the line after the origin code.
        lines = text.splitlines()
        header_ints = 0
        start = None
        for idx, line in enumerate(lines):
            if line.strip():
                header_ints += 1
            if header_ints == 6:  # dim, nc, kind, rows, cols, origin
                start = idx + 1
                break
        if start is None:
            raise ValueError(f"{path}: file ends before the CSparse listing")
        W, end = _read_csparse(text, start, m, m, path)
        tok = _Tokens("\n".join(lines[end:]), path)
    else:
        raise ValueError(f"{path}: storage kind {kind} not supported for fc2d files")
    q = tok.floats(m, "q")
    mu = tok.floats(nc, "mu")
    if sparse:
        import scipy.sparse

        W = scipy.sparse.csc_matrix(W)
    return W, q, mu
