"""Where each estimated quantity lives in a Kalman filter's state vector: an index allocator.

A filter keeps a fixed head (position, velocity, zenith delays ...) followed by blocks that come and go
with satellites (ambiguities, ionosphere, multipath).  `StateLayout` owns the state vector `x`, its
covariance `P` and the map from a block's key to its first index, so the estimators never grow, shrink
or re-index arrays by hand.  Two ways to release a block, as the estimators need them:

- ``reuse_freed=True``: the block's slots are zeroed and handed to the next block of the same size
  (last freed first); indices of the other blocks never move.  Cheap for a rover whose satellites
  come and go every few seconds.
- ``reuse_freed=False``: the block is cut out and the later blocks move down, keeping their order;
  the state stays dense.
"""
from __future__ import annotations

from collections.abc import Hashable, Iterator

import numpy as np


class StateLayout:
    """The state vector, its covariance and the index of every block in it."""

    def __init__(self, x0, P0, reuse_freed: bool = True):
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float).reshape(self.x.size, self.x.size)
        self.head = self.x.size  # states before the first block
        self.reuse_freed = bool(reuse_freed)
        self._start: dict[Hashable, int] = {}
        self._size: dict[Hashable, int] = {}
        self._free: dict[int, list[int]] = {}  # block size -> released starts, last released at the end

    # --- queries --------------------------------------------------------------------------------

    def __contains__(self, key: Hashable) -> bool:
        return key in self._start

    def __len__(self) -> int:
        return len(self._start)

    def __iter__(self) -> Iterator[Hashable]:
        return iter(self._start)

    def index(self, key: Hashable) -> int:
        """The first state index of a block."""
        return self._start[key]

    def get(self, key: Hashable, default=None):
        return self._start.get(key, default)

    def indices(self, keys) -> np.ndarray:
        """The first state index of each of several blocks."""
        return np.array([self._start[k] for k in keys], dtype=int)

    def items(self):
        """(key, first index) of every block, in the order they were added."""
        return self._start.items()

    # --- changes --------------------------------------------------------------------------------

    def add(self, key: Hashable, values, variances) -> int:
        """A new block with independent prior variances; returns its first index."""
        values = np.atleast_1d(np.asarray(values, dtype=float))
        variances = np.atleast_1d(np.asarray(variances, dtype=float))
        if key in self._start:
            raise KeyError(f"state block {key!r} already present")
        if values.shape != variances.shape or values.ndim != 1:
            raise ValueError("a block's values and variances must be equal 1-D arrays")
        m = values.size
        free = self._free.get(m)
        if free:
            i = free.pop()
        else:
            i = self.x.size
            self.x = np.concatenate([self.x, np.zeros(m)])
            P = np.zeros((i + m, i + m))
            P[:i, :i] = self.P
            self.P = P
        self.reset(i, values, variances)
        self._start[key] = i
        self._size[key] = m
        return i

    def reset(self, i: int, values, variances) -> None:
        """Restart states i, i+1, ... uncorrelated with the rest, with the given values and variances."""
        values = np.atleast_1d(np.asarray(values, dtype=float))
        variances = np.atleast_1d(np.asarray(variances, dtype=float))
        sl = slice(i, i + values.size)
        self.x[sl] = values
        self.P[sl, :] = 0.0
        self.P[:, sl] = 0.0
        self.P[sl, sl] = np.diag(variances)

    def remove(self, keys) -> None:
        """Release the blocks of `keys` that are present."""
        gone = [k for k in keys if k in self._start]
        if not gone:
            return
        if self.reuse_freed:
            for k in gone:
                i, m = self._start.pop(k), self._size.pop(k)
                self.x[i:i + m] = 0.0
                self.P[i:i + m, :] = 0.0
                self.P[:, i:i + m] = 0.0
                self._free.setdefault(m, []).append(i)
            return
        cut = np.concatenate([np.arange(self._start[k], self._start[k] + self._size[k]) for k in gone])
        for k in gone:
            del self._start[k], self._size[k]
        keep = np.setdiff1d(np.arange(self.x.size), cut)
        self.x = self.x[keep]
        self.P = self.P[np.ix_(keep, keep)]
        order = sorted(self._start, key=self._start.__getitem__)
        i = self.head
        for k in order:
            self._start[k] = i
            i += self._size[k]
