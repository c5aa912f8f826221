"""The uncertainty structure of the mu analyses: one :class:`Block` per Delta_k and the one
:class:`BlockStructure` type that validates a list of blocks once and serves every analysis
(:mod:`.mu` complex/real bounds and their index maps, :mod:`.dg_scaling` D-G scaling and
zero padding, :mod:`.mixed_mu`, :mod:`.certificate`), kept apart so that none of them imports
another in a circle.

Conventions (MATLAB ``mussv``): Delta = diag(Delta_1, ..., Delta_K) with Delta_k of size
rows_k x cols_k, so M is (sum cols_k) x (sum rows_k): M's rows are partitioned by the blocks'
``cols`` and its columns by their ``rows``, so that M Delta is defined. The blocks are
dimensionless (the uncertainty is normalised to ||Delta_k|| <= 1).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

__all__ = ["Block", "BlockKind", "BlockStructure"]

BlockKind = Literal["full", "repeated_complex", "real"]
"""The kinds of block: full complex, repeated complex scalar, repeated real scalar."""
_KINDS: tuple[str, ...] = ("full", "repeated_complex", "real")


@dataclass(frozen=True)
class Block:
    """One block Delta_k of the uncertainty structure Delta (dimensionless, ||Delta_k|| <= 1).

    Parameters
    ----------
    kind : {"full", "repeated_complex", "real"}
        ``"full"`` (full complex rows x cols block), ``"repeated_complex"`` (delta I_n,
        delta complex) or ``"real"`` (delta I_n, delta real).
    rows, cols : int
        Size of the block Delta_k (rows x cols), >= 1. Repeated blocks are square.

    Raises
    ------
    ValueError
        On an unknown kind, a size that is not a positive integer, or a non-square repeated
        block.

    Examples
    --------
    >>> Block.full(2, 1)
    Block(kind='full', rows=2, cols=1)
    >>> Block.real(3).rows
    3
    """

    kind: BlockKind
    rows: int
    cols: int

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise ValueError(f"unknown block kind {self.kind!r}; expected one of {_KINDS}")
        for name in ("rows", "cols"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
                raise ValueError(f"Block.{name} must be a positive integer, got {v!r}")
        if self.kind != "full" and self.rows != self.cols:
            raise ValueError(
                f"a {self.kind} block (delta * I_n) must be square, got {self.rows}x{self.cols}"
            )

    @staticmethod
    def full(rows: int, cols: int | None = None) -> Block:
        """Full complex block of size rows x cols.

        Parameters
        ----------
        rows : int
            Rows of Delta_k (= columns of M it closes a loop around).
        cols : int, optional
            Columns of Delta_k; defaults to ``rows``.

        Returns
        -------
        Block
            The ``"full"`` block.
        """
        return Block("full", int(rows), int(rows if cols is None else cols))

    @staticmethod
    def repeated_complex(n: int) -> Block:
        """Repeated complex scalar block delta * I_n.

        Parameters
        ----------
        n : int
            Number of repetitions (the block is n x n).

        Returns
        -------
        Block
            The ``"repeated_complex"`` block.
        """
        return Block("repeated_complex", int(n), int(n))

    @staticmethod
    def real(n: int = 1) -> Block:
        """Repeated real scalar block delta * I_n (delta real).

        Parameters
        ----------
        n : int, optional
            Number of repetitions (the block is n x n); 1 is a plain real parameter.

        Returns
        -------
        Block
            The ``"real"`` block.
        """
        return Block("real", int(n), int(n))


_MAP_NAMES = frozenset((
    "n", "K", "row_idx", "col_idx", "blk_of_row", "blk_of_col", "is_full", "is_real",
    "all_square", "scalar", "rep_blocks", "rep_row", "rep_col", "rep_blk",
    "full_row", "full_col", "row_starts", "col_starts", "diag_param_l", "diag_param_r",
    "block_param_slices", "n_params", "off_il", "off_jl", "off_ir", "off_jr", "off_pre",
    "off_pim", "has_off",
))
"""Attributes that :meth:`BlockStructure._index` sets."""


def _cat(parts: list[NDArray[np.intp]]) -> NDArray[np.intp]:
    return np.concatenate(parts) if parts else np.zeros(0, np.intp)


class BlockStructure:
    """A block-diagonal uncertainty structure, the shape of the M it applies to, and its maps.

    Validated once at construction (building a ``BlockStructure`` from a ``BlockStructure``
    reuses it). Besides the shapes it holds the index maps that the mu bounds use: where each
    block sits in M's rows and columns and how the D-scaling parameter vector of
    :func:`vtolftc.synthesis.mu.mu_upper_bound` fills D_l and D_r (computed together on the
    first access of any of them, so that the D-G analyses, which need only the shapes, do not
    pay for them).

    Parameters
    ----------
    blocks : sequence of Block, Block or BlockStructure
        The blocks in order. ``Block.full(r, c)`` is an r x c complex block;
        ``Block.real(n)`` / ``Block.repeated_complex(n)`` are delta I_n.

    Attributes
    ----------
    blocks : tuple of Block
        The blocks.
    m_shape, delta_shape : tuple of int
        (rows, cols) of M = (sum of block cols, sum of block rows) and of Delta (transposed).
    n : int
        Rows of M (sum of block cols); M is n x n when :attr:`square`.
    K : int
        Number of blocks.
    row_idx, col_idx : list of ndarray of int
        Positions of block k in M's rows (``cols_k`` of them) and columns (``rows_k``).
    is_full, is_real : ndarray of bool, shape (K,)
        Block kinds.
    has_real, all_square, scalar : bool
        A real block is present; every block is square; every block is 1 x 1.
    n_params : int
        Length of the D-scaling parameter vector (log-diagonal and off-diagonal entries of
        the upper-triangular scalings of repeated blocks).

    Raises
    ------
    ValueError
        If the structure is empty or an entry is not a :class:`Block`.

    Examples
    --------
    >>> st = BlockStructure([Block.full(1, 2), Block.real(1)])
    >>> st.m_shape, st.delta_shape
    ((3, 2), (2, 3))
    >>> BlockStructure([Block.full(2), Block.real(1)]).ab13md_spec()
    (array([2, 1]), array([2, 1]))
    """

    blocks: tuple[Block, ...]

    def __init__(self, blocks: Sequence[Block] | Block | BlockStructure):
        if isinstance(blocks, BlockStructure):
            self.__dict__.update(blocks.__dict__)  # validated once: share its maps
            return
        if isinstance(blocks, Block):
            blocks = [blocks]
        blocks = tuple(blocks)
        if not blocks:
            raise ValueError("the block structure is empty; expected a list of Block objects")
        for b in blocks:
            if not isinstance(b, Block):
                raise ValueError(
                    f"unknown block specification {b!r}; expected Block.full(rows, cols), "
                    "Block.repeated_complex(n) or Block.real(n)"
                )
        self.__dict__["blocks"] = blocks

    def __getattr__(self, name: str) -> Any:
        # only called for attributes not yet set: the index maps, built on first use
        if name in _MAP_NAMES and "blocks" in self.__dict__:
            self._index(self.__dict__["blocks"])
            return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"BlockStructure is immutable (cannot set {name!r})")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BlockStructure):
            return NotImplemented
        return self.blocks == other.blocks

    def __hash__(self) -> int:
        return hash(self.blocks)

    def __repr__(self) -> str:
        return f"BlockStructure(blocks={self.blocks!r})"

    def _index(self, blocks: tuple[Block, ...]) -> None:
        """Index maps of M's rows/columns and the D-scaling parametrisation (set once)."""
        a: dict[str, Any] = {}
        n_rows = sum(b.cols for b in blocks)
        n_cols = sum(b.rows for b in blocks)
        a["n"] = n_rows
        a["K"] = len(blocks)
        row_idx: list[NDArray[np.intp]] = []  # positions in M's row space (cols_k)
        col_idx: list[NDArray[np.intp]] = []  # positions in M's column space (rows_k)
        r0 = c0 = 0
        for b in blocks:
            row_idx.append(np.arange(r0, r0 + b.cols))
            col_idx.append(np.arange(c0, c0 + b.rows))
            r0 += b.cols
            c0 += b.rows
        a["row_idx"], a["col_idx"] = row_idx, col_idx
        a["blk_of_row"] = np.concatenate([np.full(b.cols, k) for k, b in enumerate(blocks)])
        a["blk_of_col"] = np.concatenate([np.full(b.rows, k) for k, b in enumerate(blocks)])
        a["is_full"] = np.array([b.kind == "full" for b in blocks])
        a["is_real"] = np.array([b.kind == "real" for b in blocks])
        a["all_square"] = all(b.rows == b.cols for b in blocks)
        a["scalar"] = all(b.rows == b.cols == 1 for b in blocks)
        # element maps for repeated blocks (row position -> column position)
        rep = [k for k, b in enumerate(blocks) if b.kind != "full"]
        full = [k for k, b in enumerate(blocks) if b.kind == "full"]
        a["rep_blocks"] = rep
        a["rep_row"] = _cat([row_idx[k] for k in rep])
        a["rep_col"] = _cat([col_idx[k] for k in rep])
        a["rep_blk"] = a["blk_of_row"][a["rep_row"]]
        a["full_row"] = _cat([row_idx[k] for k in full])
        a["full_col"] = _cat([col_idx[k] for k in full])
        a["row_starts"] = np.array([ix[0] for ix in row_idx])
        a["col_starts"] = np.array([ix[0] for ix in col_idx])
        # D-scaling parametrisation: parameter index of every diagonal entry of D_l (rows) /
        # D_r (cols), and of the strictly upper entries of repeated blocks (re, im parts)
        diag_l = np.zeros(n_rows, np.intp)
        diag_r = np.zeros(n_cols, np.intp)
        off: dict[str, list[int]] = {k: [] for k in ("il", "jl", "ir", "jr", "pre", "pim")}
        p = 0
        slices: list[slice] = []
        for k, b in enumerate(blocks):
            start = p
            if b.kind == "full":
                diag_l[row_idx[k]] = p
                diag_r[col_idx[k]] = p
                p += 1
            else:
                m = b.rows
                diag_l[row_idx[k]] = p + np.arange(m)
                diag_r[col_idx[k]] = p + np.arange(m)
                p += m
                iu, ju = np.triu_indices(m, 1)
                nu = iu.size
                off["il"].extend(row_idx[k][iu])
                off["jl"].extend(row_idx[k][ju])
                off["ir"].extend(col_idx[k][iu])
                off["jr"].extend(col_idx[k][ju])
                off["pre"].extend(range(p, p + nu))
                off["pim"].extend(range(p + nu, p + 2 * nu))
                p += 2 * nu
            slices.append(slice(start, p))
        a["diag_param_l"], a["diag_param_r"] = diag_l, diag_r
        a["block_param_slices"] = slices
        a["n_params"] = p
        for key, v in off.items():
            a[f"off_{key}"] = np.array(v, np.intp)
        a["has_off"] = a["off_il"].size > 0
        self.__dict__.update(a)

    # attributes set by _index (declared for type checkers)
    n: int
    K: int
    row_idx: list[NDArray[np.intp]]
    col_idx: list[NDArray[np.intp]]
    blk_of_row: NDArray[np.intp]
    blk_of_col: NDArray[np.intp]
    is_full: NDArray[np.bool_]
    is_real: NDArray[np.bool_]
    all_square: bool
    scalar: bool
    rep_blocks: list[int]
    rep_row: NDArray[np.intp]
    rep_col: NDArray[np.intp]
    rep_blk: NDArray[np.intp]
    full_row: NDArray[np.intp]
    full_col: NDArray[np.intp]
    row_starts: NDArray[np.intp]
    col_starts: NDArray[np.intp]
    diag_param_l: NDArray[np.intp]
    diag_param_r: NDArray[np.intp]
    block_param_slices: list[slice]
    n_params: int
    off_il: NDArray[np.intp]
    off_jl: NDArray[np.intp]
    off_ir: NDArray[np.intp]
    off_jr: NDArray[np.intp]
    off_pre: NDArray[np.intp]
    off_pim: NDArray[np.intp]
    has_off: bool

    @property
    def m_shape(self) -> tuple[int, int]:
        """Shape (rows, cols) of the matrix M that the structure closes a loop around."""
        return sum(b.cols for b in self.blocks), sum(b.rows for b in self.blocks)

    @property
    def delta_shape(self) -> tuple[int, int]:
        """Shape (rows, cols) of the block-diagonal perturbation Delta."""
        return sum(b.rows for b in self.blocks), sum(b.cols for b in self.blocks)

    @property
    def has_real(self) -> bool:
        """True when a block is a real (parametric) scalar block."""
        return any(b.kind == "real" for b in self.blocks)

    @property
    def square(self) -> bool:
        """True when M (and Delta) is square: sum of block rows = sum of block cols."""
        rows, cols = self.m_shape
        return rows == cols

    def require_square(self, n: int) -> BlockStructure:
        """Check that the structure fits a square n x n matrix M.

        Parameters
        ----------
        n : int
            Size of M.

        Returns
        -------
        BlockStructure
            ``self``.

        Raises
        ------
        ValueError
            If the sum of block rows or of block cols differs from n.
        """
        sum_r, sum_c = self.delta_shape
        if sum_r != n or sum_c != n:
            raise ValueError(
                f"block sizes do not match M: sum of block rows = {sum_r}, sum of block "
                f"cols = {sum_c}, but M is {n}x{n} (both sums must equal {n})"
            )
        return self

    def ab13md_spec(self) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
        """Block description for SLICOT AB13MD, if the structure is within its scope.

        AB13MD takes square full complex blocks and 1 x 1 real blocks only.

        Returns
        -------
        tuple of ndarray or None
            (nblock, itype), each of shape (K,): block sizes and kinds (2 complex, 1 real);
            None if a block is outside AB13MD's scope.
        """
        nblock, itype = [], []
        for b in self.blocks:
            if b.kind == "full" and b.rows == b.cols:
                nblock.append(b.rows)
                itype.append(2)
            elif b.kind == "real" and b.rows == 1:
                nblock.append(1)
                itype.append(1)
            else:
                return None
        return np.array(nblock, dtype=np.int64), np.array(itype, dtype=np.int64)

    def check(self, M: Any) -> NDArray[np.complex128]:
        """M as a complex array, with a one-line error if its shape does not fit.

        Parameters
        ----------
        M : array_like, shape ``m_shape``
            The matrix the structure closes a loop around (finite entries).

        Returns
        -------
        ndarray of complex, shape ``m_shape``
            M as complex.

        Raises
        ------
        ValueError
            If M is not 2-D, has the wrong shape, or holds NaN or inf.
        """
        M = np.asarray(M)
        if M.ndim != 2:
            raise ValueError(f"M must be a 2-D matrix, got shape {M.shape}")
        if M.shape != self.m_shape:
            raise ValueError(
                f"M is {M.shape[0]}x{M.shape[1]} but the block structure needs "
                f"{self.m_shape[0]}x{self.m_shape[1]} (rows = sum of block cols, cols = sum "
                "of block rows)"
            )
        if not np.all(np.isfinite(M)):
            raise ValueError("M contains NaN or inf entries")
        return M.astype(complex)

    # padding to square blocks -----------------------------------------------------------
    def padded(self) -> tuple[BlockStructure, NDArray[np.intp], NDArray[np.intp]]:
        """Square-block structure and the positions of M's rows/cols in the padded M.

        Returns
        -------
        structure : BlockStructure
            Every non-square full block r x c replaced by a square max(r, c) block.
        rows, cols : ndarray of int
            Positions of M's rows (shape ``(m_shape[0],)``) and columns (``(m_shape[1],)``)
            in the padded square M.
        """
        rows_keep: list[int] = []
        cols_keep: list[int] = []
        new: list[Block] = []
        r0 = 0
        for b in self.blocks:
            s = max(b.rows, b.cols)
            rows_keep.extend(range(r0, r0 + b.cols))  # M rows of this block: b.cols
            cols_keep.extend(range(r0, r0 + b.rows))  # M cols of this block: b.rows
            new.append(Block.full(s) if b.kind == "full" else b)
            r0 += s
        return BlockStructure(new), np.array(rows_keep, np.intp), np.array(cols_keep, np.intp)

    def pad(self, M: NDArray[Any]) -> tuple[NDArray[np.complex128], BlockStructure]:
        """Zero-padded square M and its square-block structure (mu is unchanged).

        Parameters
        ----------
        M : ndarray, shape ``m_shape``
            The matrix (as returned by :meth:`check`).

        Returns
        -------
        M_padded : ndarray of complex, shape (N, N)
            M with zero rows/columns inserted (M itself if no padding is needed).
        structure : BlockStructure
            The square-block structure of ``M_padded``.
        """
        sq, rk, ck = self.padded()
        if self.m_shape[0] == len(rk) == len(ck) and np.array_equal(rk, ck) and (
            rk.size == 0 or rk[-1] == rk.size - 1
        ):
            return M, sq
        n = sq.m_shape[0]
        Mp = np.zeros((n, n), dtype=complex)
        Mp[np.ix_(rk, ck)] = M
        return Mp, sq

    def unpad_delta(self, Delta: NDArray[Any]) -> NDArray[np.complex128]:
        """Delta of the padded problem restricted to this structure (drops padding).

        Parameters
        ----------
        Delta : ndarray, shape (N, N)
            Perturbation of the padded problem of :meth:`pad`.

        Returns
        -------
        ndarray of complex, shape ``delta_shape``
            The perturbation for this structure.
        """
        _, rk, ck = self.padded()
        return np.asarray(Delta)[np.ix_(ck, rk)]
