"""A fixed-size ring of float64 rows whose last n rows are always one contiguous view.

Every row is written twice, at ``pos`` and ``pos + capacity`` of a (2 * capacity, width)
buffer, so ``last(n)`` is a plain slice: no copy, no wrap-around case, and a C-contiguous
window that the numba predictor takes without compiling another kernel.  Nothing is
allocated per push.
"""

from __future__ import annotations

import numpy as np


class RowRing:
    """The last ``capacity`` rows of width ``width``; starts filled with NaN (no data)."""

    def __init__(self, capacity: int, width: int) -> None:
        if capacity < 1 or width < 1:
            raise ValueError(f"a ring needs capacity and width >= 1, got {capacity}, {width}")
        self.capacity = int(capacity)
        self.width = int(width)
        self._buf = np.full((2 * self.capacity, self.width), np.nan)
        self._pos = 0  # where the next row goes
        self.count = 0  # rows pushed since the last clear (saturates at capacity)

    def clear(self) -> None:
        self._buf[:] = np.nan
        self._pos = 0
        self.count = 0

    def push(self, row: np.ndarray) -> None:
        """Copy ``row`` (length ``width``) in as the newest row."""
        buf, pos = self._buf, self._pos
        buf[pos] = row
        buf[pos + self.capacity] = row
        pos += 1
        self._pos = 0 if pos == self.capacity else pos
        if self.count < self.capacity:
            self.count += 1

    def last(self, n: int) -> np.ndarray:
        """The newest ``n`` rows, oldest first, as a view (valid until the next push)."""
        if not 0 < n <= self.capacity:
            raise ValueError(f"last(n) needs 0 < n <= {self.capacity}, got {n}")
        end = self._pos + self.capacity
        return self._buf[end - n : end]

    def newest(self) -> np.ndarray:
        return self._buf[self._pos + self.capacity - 1]
