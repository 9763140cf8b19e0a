"""One table of names and limits (clrt/config.py): the kernels see the same
values as Python, no kernel source repeats them, and every entry point offers
the table's choices."""

import re
from importlib import resources

import numpy as np
import pyopencl as cl

from clrt import config
from clrt.cli import _parser
from clrt.device.context import create_context
from clrt.device.program import build_options, expand_source
from clrt.errors import InputError


def _kernel_files():
    folder = resources.files("clrt.kernels")
    return {p.name: p.read_text() for p in folder.iterdir() if p.name.endswith((".cl", ".h"))}


def test_no_kernel_source_defines_a_table_value():
    names = set(config.kernel_defines())
    for name, text in _kernel_files().items():
        defined = set(re.findall(r"^\s*#\s*define\s+(\w+)", text, re.MULTILINE))
        assert not defined & names, f"{name} defines {defined & names}, which clrt.config passes as -D"


def test_the_kernels_see_the_table(device):
    context, queue = create_context(device)
    names = sorted(config.kernel_defines())
    body = "\n".join(f"out[{i}] = (int)({n});" for i, n in enumerate(names))
    # A probe program built the way every clrt program is built (build_program's options).
    source = expand_source("layouts.h") + f"__kernel void probe(__global int* out) {{ {body} }}"

    program = cl.Program(context, source).build(options=build_options(context))
    out = np.zeros(len(names), np.int32)
    buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program.probe(queue, (1,), None, buf)
    cl.enqueue_copy(queue, out, buf)
    expected = {"MAX_BOUNCES": config.MAX_BOUNCES, "MATERIAL_SMOOTH": config.MATERIAL_SMOOTH,
                "MATERIAL_DOUBLE_SIDED": config.MATERIAL_DOUBLE_SIDED,
                "MAX_PARTS": config.MAX_PARTS, **{f"CULL_{k.upper()}": v for k, v in config.CULL_MODES.items()},
                **{f"BAD_{k.upper()}": i for i, k in enumerate(config.RAY_CHECKS)},
                **{f"WRAP_{k.upper()}": v for k, v in config.TEXTURE_WRAPS.items()},
                "TEXEL_LIMIT": config.TEXEL_LIMIT, "RESULT_SLOTS": config.RESULT_SLOTS,
                "INSTANCE_MIRROR": config.INSTANCE_MIRROR,
                "NO_RESULT": -1,   # (int) of the all-ones ulong
                "MAX_PATH_DEPTH": config.MAX_PATH_DEPTH,
                **{f"PATH_{k.upper()}": v for k, v in config.PATH_STRATEGIES.items()},
                **{f"LIGHT_{k.upper()}": v for k, v in config.LIGHT_KINDS.items()},
                "POINT_CELL_BITS": config.POINT_CELL_BITS, "POINT_OFFSETS_GROUP": config.POINT_OFFSETS_GROUP,
                "POINT_RUN_CELL_BITS": config.POINT_RUN_CELL_BITS}
    assert dict(zip(names, out.tolist())) == expected


def test_the_cli_offers_the_tables_choices():
    render = _parser()._subparsers._group_actions[0].choices["render"]
    for accel in config.ACCELS:
        for builder in config.BUILDERS:
            args = render.parse_args(["--accel", accel, "--builder", builder])
            assert (args.accel, args.builder) == (accel, builder)
    defaults = render.parse_args([])
    assert (defaults.accel, defaults.builder, defaults.leaf_size) == (
        config.DEFAULT_ACCEL, config.DEFAULT_BUILDER, config.DEFAULT_LEAF_SIZE)
    for option, bad in (("--accel", "cube"), ("--builder", "lbvh")):
        try:
            render.parse_args([option, bad])
        except InputError as exc:
            assert bad in str(exc)
        else:
            raise AssertionError(f"{option} {bad} was accepted")


def test_stack_sizes_are_shared_by_trees_of_similar_depth(device):
    assert config.stack_size(1) == config.stack_size(config.STACK_SIZE_STEP) == config.STACK_SIZE_STEP
    assert config.stack_size(config.STACK_SIZE_STEP + 1) == 2 * config.STACK_SIZE_STEP
    for depth in range(1, 200):
        assert depth <= config.stack_size(depth) < depth + config.STACK_SIZE_STEP
    # Two meshes whose trees differ in depth share one compiled program.
    from clrt.query import Accel
    from clrt.scene import primitives
    a, b = Accel(primitives.icosphere(1), device=device), Accel(primitives.icosphere(3), device=device)
    assert a.acceleration.depth != b.acceleration.depth
    assert a.kernels["query_closest"].program.int_ptr == b.kernels["query_closest"].program.int_ptr


def test_an_include_inside_a_conditional_is_refused(monkeypatch):
    from clrt.device import program as program_module
    from clrt.errors import KernelBuildError
    texts = {"entry.cl": '#ifdef X\n#include "a.cl"\n#endif\n', "a.cl": "int a;\n"}
    monkeypatch.setattr(program_module, "kernel_text", lambda name: texts[name])
    try:
        program_module.expand_source("entry.cl")
    except KernelBuildError as exc:
        assert "entry.cl:2" in str(exc) and "#if" in str(exc)
    else:
        raise AssertionError("an #include inside #ifdef was expanded")
    texts["entry.cl"] = '#ifndef ENTRY\n#define ENTRY\n#include "a.cl"\n#endif\n'    # an include guard is fine
    assert "int a;" in program_module.expand_source("entry.cl")
