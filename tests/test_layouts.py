"""The numpy dtypes in clrt.layouts and the structs in layouts.h agree byte for byte."""

import numpy as np
import pyopencl as cl

from clrt import layouts
from clrt.device.context import create_context
from clrt.device.program import build_options, expand_source


def test_every_struct_matches_its_dtype(device):
    context, queue = create_context(device)
    checks = []   # (struct, field or None for sizeof, expected bytes)
    for struct, dtype in layouts.STRUCTS.items():
        checks.append((struct, None, dtype.itemsize))
        for name in dtype.names:
            checks.append((struct, name, dtype.fields[name][1]))
    body = "\n".join(
        f"out[{i}] = {'sizeof(' + s + ')' if f is None else 'offsetof(' + s + ', ' + f + ')'};"
        for i, (s, f, _) in enumerate(checks))
    source = expand_source("layouts.h") + (
        "#define offsetof(T, f) ((uint)(size_t)&(((T*)0)->f))\n"
        f"__kernel void probe(__global uint* out) {{ {body} }}")
    program = cl.Program(context, source).build(options=build_options(context))
    out = np.zeros(len(checks), np.uint32)
    buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program.probe(queue, (1,), None, buf)
    cl.enqueue_copy(queue, out, buf)
    device_side = {(s, f): int(v) for (s, f, _), v in zip(checks, out)}
    host_side = {(s, f): e for s, f, e in checks}
    assert device_side == host_side
