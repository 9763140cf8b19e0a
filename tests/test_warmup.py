"""clrt.device.warmup: the driver started and a context made through ctypes
(the ICD loader pyopencl uses), adopted by pyopencl only for the same device."""

import numpy as np
import pyopencl as cl

from clrt.cli import _device_option
from clrt.device import warmup


def test_device_option_is_read_before_argparse():
    assert _device_option(["render", "m.off", "--device", "gpu"]) == "gpu"
    assert _device_option(["render", "--device=0:1", "m.off"]) == "0:1"
    assert _device_option(["render", "m.off"]) is None
    assert _device_option(["render", "--device"]) is None


def test_warm_context_is_adopted_for_its_device_only(device, monkeypatch):
    from clrt.device.context import create_context
    _, queue = create_context(device)
    mine = queue.device
    # The test machine may have no GPU: let the warm-up take the test device's type.
    monkeypatch.setattr(warmup, "CL_DEVICE_TYPE_GPU", int(mine.type))
    first = [d for p in cl.get_platforms() for d in p.get_devices() if d.type == mine.type][0]
    warmup._warm(True)
    made = warmup.take_context(first.int_ptr)
    assert made, "no context was made through the ICD loader"
    context = cl.Context.from_int_ptr(made, retain=False)
    assert context.devices[0].int_ptr == first.int_ptr
    buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.arange(4.0))
    out = np.empty(4)
    cl.enqueue_copy(cl.CommandQueue(context), out, buffer, is_blocking=True)
    assert np.array_equal(out, np.arange(4.0))
    warmup._warm(True)
    assert warmup.take_context(first.int_ptr + 8) is None     # another device: released, not adopted
    assert warmup.take_context(first.int_ptr) is None         # and gone


def test_start_ignores_other_devices(monkeypatch):
    monkeypatch.setattr(warmup, "_thread", None)
    warmup.start("cpu")
    warmup.start("1:0")
    assert warmup._thread is None
