"""Work over a large array in blocks, on a few host threads at once.

numpy releases the GIL inside a gather (np.take), a fancy assignment, a
reduction and a copy, so blocks of one large array run side by side on the
host's cores: the corner gather of a 50M-triangle mesh writes 1.8 GB, memory
work that one thread does at a fraction of a server's bandwidth (the staged
upload's copies, clrt.device.pinned, are spread the same way).  An array
below two blocks' worth is worked on the calling thread in one block: a
thread's hand-over costs more than it saves there.

    >>> lows = map_blocks(lambda start, stop: faces[start:stop].min(), len(faces))
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

BLOCK_ROWS = 1 << 18          # rows a block holds at least (a few ms of work)
MAX_THREADS = 8

_pool: ThreadPoolExecutor | None = None
_pool_pid = 0                 # the process that made _pool: a forked child has none of its threads
_pool_lock = threading.Lock()


def thread_count() -> int:
    """Threads the blocks of one array go to: half the host's cores (the other
    half is left to the caller's other threads and the driver), 1..MAX_THREADS."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cores // 2))


def spans(rows: int) -> list[tuple[int, int]]:
    """(start, stop) of the blocks of ``rows`` rows: one for each thread, each of
    at least BLOCK_ROWS rows (one block below two blocks' worth)."""
    count = max(1, min(thread_count(), rows // BLOCK_ROWS))
    step = max(-(-rows // count), 1)
    return [(start, min(rows, start + step)) for start in range(0, rows, step)] or [(0, 0)]


def map_blocks(work: Callable[[int, int], object], rows: int) -> list:
    """``[work(start, stop) for each block of range(rows)]``, in order, the blocks
    on the pool's threads when there are several.  ``work`` must not call
    map_blocks itself (the pool's threads would wait on each other)."""
    blocks = spans(rows)
    if len(blocks) == 1:
        return [work(*blocks[0])]
    global _pool, _pool_pid
    with _pool_lock:
        if _pool is None or _pool_pid != os.getpid():
            _pool, _pool_pid = ThreadPoolExecutor(MAX_THREADS, thread_name_prefix="clrt-blocks"), os.getpid()
    jobs = [_pool.submit(work, start, stop) for start, stop in blocks]
    return [job.result() for job in jobs]
