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


def test_render_in_a_fresh_process_with_the_warm_up(tmp_path):
    """The warm-up runs before pyopencl is imported: in a fresh process, with
    no --device (so it starts), the render must succeed.  (pyopencl's own ICD
    loader crashed there until PYOPENCL_HOME was set for it.)"""
    import os
    import subprocess
    import sys

    from clrt.scene import primitives
    mesh = primitives.icosphere(1)
    path = tmp_path / "ball.off"
    path.write_text(f"OFF\n{len(mesh.vertices)} {len(mesh.faces)} 0\n"
                    + "".join(f"{x} {y} {z}\n" for x, y, z in mesh.vertices)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in mesh.faces))
    env = {k: v for k, v in os.environ.items() if k not in ("PYOPENCL_HOME", "CLRT_WARMUP", "PYOPENCL_CTX")}
    done = subprocess.run([sys.executable, "-X", "faulthandler", "-m", "clrt", "render", str(path), "--width", "16",
                           "--height", "12", "-o", str(tmp_path / "ball.png")],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "ball.png").stat().st_size > 0
