"""A fixed-size table of samples for end-of-run plots, however long the run.

:class:`DecimatingBuffer` keeps every ``stride``-th row of a stream in a preallocated array;
when the array is full it keeps every second row and doubles the stride. A run of any length
therefore holds between ``capacity / 2`` and ``capacity`` rows spread evenly over the whole run,
in ``capacity * n_cols * 8`` bytes; a run shorter than ``capacity`` rows keeps every row, so its
plots are exactly those of an unbounded list.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["DecimatingBuffer"]


class DecimatingBuffer:
    """Evenly decimated rows of a stream, in bounded memory.

    Parameters
    ----------
    n_cols : int
        Values per row.
    capacity : int
        Rows held at most (even, >= 2).

    Examples
    --------
    >>> b = DecimatingBuffer(1, capacity=4)
    >>> for k in range(10):
    ...     b.add((float(k),))
    >>> b.stride, b.rows()[:, 0].tolist()
    (4, [0.0, 4.0, 8.0])
    """

    def __init__(self, n_cols: int, capacity: int = 16384) -> None:
        if capacity < 2 or capacity % 2:
            raise ValueError(f"capacity must be even and >= 2, got {capacity}")
        self._a = np.empty((capacity, n_cols))
        self._n = 0
        self._k = 0
        self.stride = 1
        """Stream rows per kept row (a power of two)."""

    def add(self, row: Sequence[float] | NDArray[np.float64]) -> None:
        """Offer the next row of the stream (kept if its index is a multiple of the stride)."""
        k = self._k
        self._k = k + 1
        if k % self.stride:
            return
        if self._n == self._a.shape[0]:
            half = self._n // 2
            self._a[:half] = self._a[0::2]
            self._n = half
            self.stride *= 2
            if k % self.stride:
                return
        self._a[self._n] = row
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def rows(self) -> NDArray[np.float64]:
        """The kept rows, oldest first (a view; shape ``(len(self), n_cols)``)."""
        return self._a[:self._n]
