"""Reusable recording arrays of the full model: no fresh pages on every run.

A run records its channels into arrays of tens of megabytes (a 30-design ride
batch: 14 MB at the full rate and 32 MB decimated).  Whether malloc hands back the
memory of the previous run or maps fresh pages, which the kernel must fault in and
zero, depends on the order of earlier frees and on the thread: measured, 0 to 3,700
page faults and up to 0.2 s of system time per 30-design run, so that the same run
took +-15 % from one call to the next (more in an executor thread).  The pool keeps
the arrays of finished runs and hands one out again once nothing refers to it any
more (no result, history or view of it is alive).
"""

from __future__ import annotations

import sys
import threading

import numpy as np

#: Arrays smaller than this come from numpy directly: malloc reuses small blocks well.
MIN_POOLED_BYTES = 1 << 20


class ArrayPool:
    """Float64 arrays handed out again once their last user has dropped them.

    Parameters
    ----------
    max_bytes : int
        Most bytes the pool keeps referenced; the least recently used arrays are
        forgotten beyond it (they are freed when their users drop them).
    """

    def __init__(self, max_bytes: int = 256 << 20) -> None:
        self.max_bytes = int(max_bytes)
        self._arrays: list[np.ndarray] = []
        self._lock = threading.Lock()
        self.reused = 0
        self.allocated = 0

    def empty(self, shape: tuple[int, ...]) -> np.ndarray:
        """An uninitialised float64 array of ``shape``, reused when one is free."""
        shape = tuple(int(s) for s in shape)
        if 8 * int(np.prod(shape)) < MIN_POOLED_BYTES:
            return np.empty(shape)
        with self._lock:
            for i in range(len(self._arrays)):
                array = self._arrays[i]
                # References: the list, ``array`` and getrefcount's argument; any more
                # is a result, history or view still alive somewhere.
                if array.shape == shape and sys.getrefcount(array) <= 3:
                    self._arrays.append(self._arrays.pop(i))  # most recently used last
                    self.reused += 1
                    return array
            array = np.empty(shape)
            self.allocated += 1
            self._arrays.append(array)
            while len(self._arrays) > 1 and self.nbytes > self.max_bytes:
                self._arrays.pop(0)
            return array

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays the pool holds."""
        return sum(a.nbytes for a in self._arrays)


#: The full model's recording arrays (one pool per process).
RECORDING = ArrayPool()
