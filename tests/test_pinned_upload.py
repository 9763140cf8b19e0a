"""clrt.device.pinned.upload: the staged path (page-locked blocks filled by
threads) writes exactly the array, for sizes around the block size."""

import numpy as np
import pyopencl as cl
import pytest

from clrt.device import pinned
from clrt.device.context import create_context


@pytest.mark.parametrize("staged", (True, False))
def test_upload_writes_the_array(device, staged, monkeypatch):
    context, queue = create_context(device)
    monkeypatch.setattr(pinned, "STAGE_BYTES", 1 << 20)       # several blocks from a few MB
    rng = np.random.default_rng(3)
    for nbytes in (4, (1 << 20) - 4, 1 << 20, 5 * (1 << 20) + 12, 9 * (1 << 20) + 4):
        array = rng.integers(0, 2 ** 31, nbytes // 4, dtype=np.int32)
        buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE, array.nbytes)
        pinned.upload(context, queue, buffer, array, staged=staged)
        back = np.empty_like(array)
        cl.enqueue_copy(queue, back, buffer, is_blocking=True)
        assert np.array_equal(back, array), nbytes
    pinned._stages.pop(context.int_ptr, None)               # blocks of the patched size


def test_parallel_copy_is_a_copy():
    src = np.arange(9_000_001, dtype=np.uint8)
    for threads in (1, 3, 8):
        dst = np.zeros_like(src)
        pinned._parallel_copy(dst, src, threads)
        assert np.array_equal(dst, src), threads
