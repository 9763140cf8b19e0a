"""Page-locked host memory for results, reused once the caller lets go.

The device writes a frame's image or a query's results straight into
page-locked memory by DMA, several times faster than into ordinary (pageable)
memory, and no host copy follows.  Allocating page-locked memory is slow, so
it is pooled.  Each block handed out is a numpy array whose base is a
:class:`_Lease`: every view of it keeps the lease alive, and when the last one
goes the lease returns its memory to the pool.  So results a caller keeps are
never reused.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl


class _Lease:
    """One pooled buffer lent out; ``__array_interface__`` makes numpy arrays
    over its memory whose base is this object."""

    def __init__(self, free: list, mapped: np.ndarray, nbytes: int):
        self._free, self._mapped = free, mapped
        self.__array_interface__ = {"shape": (nbytes,), "typestr": "|u1", "version": 3,
                                    "data": (mapped.__array_interface__["data"][0], False)}

    def __del__(self):
        self._free.append(self._mapped)


class PinnedPool:
    """Up to ``size`` page-locked byte buffers of one context, none larger than
    ``max_bytes`` (page-locked memory is a scarce resource of the whole system)."""

    def __init__(self, context: cl.Context, queue: cl.CommandQueue, size: int = 3, max_bytes: int = 1 << 30):
        self.context, self.queue, self.size, self.max_bytes = context, queue, size, max_bytes
        self._free: list[np.ndarray] = []    # mapped buffers not lent out
        self._count = 0                      # buffers made (free or lent)

    def take(self, nbytes: int) -> np.ndarray | None:
        """(nbytes,) uint8 page-locked, or None when all buffers are lent out or
        page-locked memory is scarce (the caller then uses ordinary memory)."""
        for k, mapped in enumerate(self._free):
            if len(mapped) >= nbytes:
                del self._free[k]
                return np.asarray(_Lease(self._free, mapped, nbytes))
        if self._free:                       # free but too small for this frame: make room
            self._count -= 1
            self._free.pop()
        if self._count >= self.size or nbytes > self.max_bytes:
            return None
        try:
            buffer = cl.Buffer(self.context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, nbytes)
            mapped, _ = cl.enqueue_map_buffer(self.queue, buffer, cl.map_flags.READ | cl.map_flags.WRITE,
                                              0, (nbytes,), np.uint8)
        except (cl.Error, MemoryError):
            return None
        self._count += 1
        return np.asarray(_Lease(self._free, mapped, nbytes))

    def buffers(self) -> int:
        """Page-locked buffers made so far and still pooled or lent."""
        return self._count
