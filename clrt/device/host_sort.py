"""The device builder's sort of (Morton code, triangle id) pairs, done by the
host for CPU devices (clrt.device.build chooses by device type).

A CPU device's memory is the host's, so reading the keys and writing them
back sorted costs a copy each; numpy's stable sorts of 16-bit digits are
radix sorts.  Warm on the 2-core development machine (PoCL): bunny00, 75k
keys, 1.5 ms against 3.5 ms for the device's 24 launches; 1M keys 35 against
110 ms.  What it saves is the first call's: PoCL compiles each kernel at its
first launch, and the device sort's three kernels took 0.3-0.6 s of a cold
``clrt render`` (docs/benchmarks.md, "The first call with empty caches").

The order is the device sort's (build_sort.cl): stable by the whole 32-bit
key, so equal keys keep their input order.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl


def stable_key_order(keys: np.ndarray) -> np.ndarray:
    """The permutation that sorts uint32 ``keys`` stably: a least-significant-
    digit sort by the low then the high 16 bits."""
    order = np.argsort((keys & 0xFFFF).astype(np.uint16), kind="stable")
    return order[np.argsort((keys[order] >> 16).astype(np.uint16), kind="stable")]


def sort_on_host(queue: cl.CommandQueue, n: int, keys: cl.Buffer, ids: cl.Buffer,
                 keep_keys: bool = True) -> cl.Buffer:
    """Sort the n (key, id) pairs in ``keys`` and ``ids`` (uint32 each) by
    key, in place, once the launches queued before are done; returns ``ids``.
    The ids are the places 0 .. n - 1 (morton_codes writes them so), so the
    sorted ids are the sort's order itself: only the keys are read.  The
    sorted keys are written back only where ``keep_keys`` (a partitioned
    build reads their segments); the writes are queued, not waited for (the
    launches after them, on the same queue, see them)."""
    host_keys = np.empty(n, np.uint32)
    cl.enqueue_copy(queue, host_keys, keys, is_blocking=True)
    order = stable_key_order(host_keys)
    cl.enqueue_copy(queue, ids, order.astype(np.uint32), is_blocking=False)
    if keep_keys:
        cl.enqueue_copy(queue, keys, host_keys[order], is_blocking=False)
    return ids
