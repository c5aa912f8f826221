"""The uncertainty block type shared by the mu analyses (:mod:`.mu`, :mod:`.dg_scaling`,
:mod:`.mixed_mu`), kept apart so that none of them imports another in a circle."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["Block", "BlockKind"]

BlockKind = Literal["full", "repeated_complex", "real"]
"""The kinds of block: full complex, repeated complex scalar, repeated real scalar."""
_KINDS: tuple[str, ...] = ("full", "repeated_complex", "real")


@dataclass(frozen=True)
class Block:
    """One block of the uncertainty structure Delta.

    kind:
        ``"full"`` (full complex rows x cols block), ``"repeated_complex"`` (delta I_n,
        delta complex) or ``"real"`` (delta I_n, delta real).
    rows, cols:
        Size of the block Delta_k (rows x cols). Repeated blocks are square.
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
        """Full complex block of size rows x cols (cols defaults to rows)."""
        return Block("full", int(rows), int(rows if cols is None else cols))

    @staticmethod
    def repeated_complex(n: int) -> Block:
        """Repeated complex scalar block delta * I_n."""
        return Block("repeated_complex", int(n), int(n))

    @staticmethod
    def real(n: int = 1) -> Block:
        """Repeated real scalar block delta * I_n (delta real)."""
        return Block("real", int(n), int(n))
