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

import threading

import numpy as np
import pyopencl as cl

from clrt.device.context import device_kind


def mapped_block(context: cl.Context, queue: cl.CommandQueue, nbytes: int) -> np.ndarray:
    """(nbytes,) uint8 over a page-locked buffer (ALLOC_HOST_PTR, mapped for
    the host); the array keeps the mapping, which keeps the buffer.  Raises
    cl.Error or MemoryError when the system has none to give."""
    buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, nbytes)
    mapped, _ = cl.enqueue_map_buffer(queue, buffer, cl.map_flags.READ | cl.map_flags.WRITE, 0, (nbytes,),
                                      np.uint8)
    return mapped


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
            mapped = mapped_block(self.context, self.queue, nbytes)
        except (cl.Error, MemoryError):
            return None
        self._count += 1
        return np.asarray(_Lease(self._free, mapped, nbytes))

    def buffers(self) -> int:
        """Page-locked buffers made so far and still pooled or lent."""
        return self._count


# ----------------------------------------------------------------------------- staged upload

# One page-locked staging block; two are kept per context.  A block is filled
# whole before its copy is sent: sending it in pieces of 1-4 MB, the device
# reading one while the host fills the next, was slower on an H200
# (docs/benchmarks.md, 2026-12-02).
STAGE_BYTES = 64 << 20
STAGED_MIN_BYTES = 16 << 20  # smaller arrays go straight to the driver
PARALLEL_COPY_MIN_BYTES = 4 << 20   # smaller copies into a staging block take one thread
_stages: dict[int, list] = {}
_stage_lock = threading.Lock()
_copier = None               # thread pool for the host copies into the staging blocks


def _copy_threads() -> int:
    import os
    return max(1, min(8, (os.cpu_count() or 1) // 2))


def _cast(dst: np.ndarray, src: np.ndarray) -> None:
    """dst[:] = src, converted as ``astype`` converts (beyond float32: inf; the
    kernels report it), in the calling thread's own error state."""
    with np.errstate(over="ignore"):
        np.copyto(dst, src, casting="unsafe")


def _parallel_copy(dst: np.ndarray, src: np.ndarray, threads: int | None = None) -> None:
    """dst[:] = src (converted to dst's dtype where the two differ) in slices on
    a few threads (numpy releases the GIL while copying)."""
    global _copier
    threads = threads or _copy_threads()
    if threads == 1 or dst.nbytes < PARALLEL_COPY_MIN_BYTES:
        _cast(dst, src)
        return
    if _copier is None:
        from concurrent.futures import ThreadPoolExecutor
        _copier = ThreadPoolExecutor(8, thread_name_prefix="clrt-stage")
    step = -(-len(src) // threads)
    jobs = [_copier.submit(_cast, dst[k:k + step], src[k:k + step]) for k in range(0, len(src), step)]
    for job in jobs:
        job.result()


def _staging_blocks(context: cl.Context, queue: cl.CommandQueue) -> list | None:
    """The context's two staging blocks, each [block, its last copy not yet
    waited for, or None]; None where page-locked memory is scarce.  Call under _stage_lock."""
    stages = _stages.get(context.int_ptr)
    if stages is None:
        try:
            stages = [[mapped_block(context, queue, STAGE_BYTES), None] for _ in range(2)]
        except (cl.Error, MemoryError):
            return None
        _stages[context.int_ptr] = stages
    return stages


def upload_together(context: cl.Context, queue: cl.CommandQueue, copies, staged: bool | None = None) -> list:
    """upload of each (buffer, array) of ``copies``, sent one after the other
    (a mesh's vertices and faces), the staged copy chosen once for them all
    (``staged`` None): where their bytes together reach STAGED_MIN_BYTES on a
    GPU -- a 1M-triangle mesh's 6 + 12 MB, each below it, took the driver's
    pageable copy in 3.7 ms on the H200.  Returns the copies' events."""
    if staged is None:
        staged = sum(a.nbytes for _, a in copies) >= STAGED_MIN_BYTES and device_kind(queue.device) == "gpu"
    return [upload(context, queue, buffer, array, staged) for buffer, array in copies]


def upload(context: cl.Context, queue: cl.CommandQueue, buffer: cl.Buffer, array: np.ndarray,
           staged: bool | None = None, dtype=None) -> cl.Event:
    """Copy a host array into ``buffer`` (from offset 0) as ``dtype`` (default
    its own; converted on the way as ``astype`` converts); returns the event of
    the last copy.  pyopencl waits for a copy whose event is let go: keep the
    event until the queue has run it, so that the host need not wait.

    A GPU reads ordinary (pageable) memory through the driver's own staging,
    one thread copying into it: about 8 GB/s on the H200's host, so two thirds
    of a 10M-triangle device build.  Large arrays go through two page-locked
    blocks instead, filled (and converted: one pass over the caller's array)
    by several threads while the device reads the other block.  CPU devices
    and arrays below STAGED_MIN_BYTES take the plain copy (``staged`` None);
    True or False choose (ray chunks, tests, benchmarks).
    """
    dtype = np.dtype(array.dtype if dtype is None else dtype)
    item = dtype.itemsize
    if staged is None:
        staged = array.size * item >= STAGED_MIN_BYTES and device_kind(queue.device) == "gpu"
    # One upload at a time per context: the blocks are the context's, and
    # each thread may have its own Accel on the process's one context.
    with _stage_lock:
        stages = _staging_blocks(context, queue) if staged else None
        if stages is not None:
            return _staged_copy(queue, buffer, array.reshape(-1), dtype, stages)
    with np.errstate(over="ignore"):   # the plain copy (also where page-locked memory is scarce)
        host = np.ascontiguousarray(array, dtype)
    return cl.enqueue_copy(queue, buffer, host, is_blocking=False)


def _staged_copy(queue: cl.CommandQueue, buffer: cl.Buffer, flat: np.ndarray, dtype: np.dtype,
                 stages: list) -> cl.Event | None:
    """upload's staged path: ``flat`` (1-D, any dtype) as ``dtype`` through the blocks."""
    item = dtype.itemsize
    per_block = STAGE_BYTES // item
    event = None
    for start in range(0, len(flat), per_block):
        # The blocks take turns across calls too: successive small uploads (a
        # ray chunk's arrays) fill one block while the device reads the other.
        stage = stages[0]
        stages.append(stages.pop(0))
        if stage[1] is not None:
            stage[1].wait()                           # the device has read this block's last chunk
        chunk = flat[start:start + per_block]
        target = stage[0][:len(chunk) * item].view(dtype)
        _parallel_copy(target, chunk)
        # Kept in the block's entry: letting the event go would wait for it.
        event = stage[1] = cl.enqueue_copy(queue, buffer, target, dst_offset=start * item, is_blocking=False)
        queue.flush()                                 # the device reads it while the host fills the next block
    return event
