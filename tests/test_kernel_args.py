"""The argument types declared for every kernel (clrt.device.program.typed_kernel)
match the kernels' own parameter lists, as the OpenCL compiler reports them:
a scalar declared with the wrong type would reach the kernel as garbage."""

import numpy as np
import pyopencl as cl
import pytest
from pyopencl import cltypes

from clrt.device.program import build_options, expand_source
from clrt.query import Accel
from clrt.renderer import Renderer
from clrt.scene import primitives
from clrt.scene.scene import Light, Material, Scene, SceneObject, scene_from_mesh
from clrt.scene.texture import Texture

# numpy dtype of a declared scalar -> the OpenCL type name clGetKernelArgInfo reports
TYPE_NAMES = {np.dtype(np.uint32): "uint", np.dtype(np.int32): "int", np.dtype(np.float32): "float",
              np.dtype(np.uint64): "ulong", np.dtype(cltypes.float4): "float4"}


def _check(context, entry, defines, kernels):
    source = expand_source(entry)
    options = build_options(context, defines) + ["-cl-kernel-arg-info"]
    program = cl.Program(context, source).build(options=options)
    for name, kernel in kernels.items():
        reference = cl.Kernel(program, name)
        declared = kernel.arg_types
        assert reference.num_args == len(declared), f"{name}: {len(declared)} types for {reference.num_args} args"
        for i, dtype in enumerate(declared):
            actual = reference.get_arg_info(i, cl.kernel_arg_info.TYPE_NAME).strip()
            if dtype is None:
                assert actual.endswith("*"), f"{name} argument {i}: declared a buffer, the kernel has {actual}"
            else:
                assert TYPE_NAMES[np.dtype(dtype)] == actual, f"{name} argument {i}: declared {dtype}, is {actual}"


@pytest.mark.parametrize("max_buffer_bytes", [None, 32768], ids=["whole", "split"])
def test_declared_argument_types_match_the_kernels(device, max_buffer_bytes):
    mesh = primitives.icosphere(3)
    renderer = Renderer(scene_from_mesh(mesh), device=device, max_buffer_bytes=max_buffer_bytes)
    assert (renderer.geometry.parts() > 1) == (max_buffer_bytes is not None)
    _check(renderer.context, "render.cl", renderer.geometry.defines, renderer.kernels)
    # A scene with corner colours and a texture: the -DSURFACE_DETAIL parameters too.
    colours = np.random.default_rng(1).random((len(mesh.faces), 3, 3))
    texture = Texture(np.zeros((4, 4, 3), np.uint8), "repeat", "repeat")
    detail = Scene([SceneObject(mesh.with_detail(colors=colours), Material(texture=texture))], [Light((2, 3, 4))])
    textured = Renderer(detail, device=device, max_buffer_bytes=max_buffer_bytes)
    _check(textured.context, "render.cl", {**textured.geometry.defines, "SURFACE_DETAIL": None}, textured.kernels)
    for accel in ("box", "none"):
        queries = Accel(mesh, accel=accel, device=device, max_buffer_bytes=max_buffer_bytes)
        _check(queries.context, "trace.cl", queries.geometry.defines, queries.kernels)


def test_the_device_builders_declared_types_match(device):
    from types import SimpleNamespace

    from clrt.device.build import _ARG_TYPES, _KERNELS, build_defines, device_kind
    from clrt.device.context import create_context
    context, queue = create_context(device)
    assert sorted(_ARG_TYPES) == sorted(_KERNELS)
    declared = {name: SimpleNamespace(arg_types=types) for name, types in _ARG_TYPES.items()}
    _check(context, "build_bvh.cl", build_defines("box", device_kind(queue.device)), declared)
