"""Every kernel's signature table (clrt.device.signature) matches the kernel's
own parameter list, as the OpenCL compiler reports it -- names and types, in
every program the renderer, the queries and the device builder build -- and
no kernel takes more than MAX_KERNEL_PARAMS parameters: a value declared with
the wrong type would reach the kernel as garbage, and long positional lists
are what the tables replaced."""

import numpy as np
import pyopencl as cl
import pytest

from clrt import layouts
from clrt.device.program import build_options, expand_source
from clrt.device.signature import MAX_KERNEL_PARAMS
from clrt.query import Accel
from clrt.renderer import Renderer
from clrt.renderer.path import PathTracer
from clrt.scene import primitives
from clrt.scene.scene import Light, Material, Scene, SceneObject, scene_from_mesh
from clrt.scene.texture import Texture

# numpy dtype of a declared scalar -> the OpenCL type name clGetKernelArgInfo reports
TYPE_NAMES = {np.dtype(np.uint32): "uint", np.dtype(np.int32): "int", np.dtype(np.float32): "float",
              np.dtype(np.float64): "double",
              np.dtype(np.uint64): "ulong", **{dtype: name for name, dtype in layouts.STRUCTS.items()}}


def _check(context, entry, defines, kernels, split=False):
    source = expand_source(entry)
    options = build_options(context, defines) + ["-cl-kernel-arg-info"]
    program = cl.Program(context, source).build(options=options)
    assert sorted(k.function_name for k in program.all_kernels()) == sorted(kernels), entry
    for name, kernel in kernels.items():
        reference = cl.Kernel(program, name)
        declared = list(zip(kernel.arg_names, kernel.arg_types))
        assert reference.num_args == len(declared), f"{name}: {len(declared)} declared for {reference.num_args}"
        if not split:
            assert reference.num_args <= MAX_KERNEL_PARAMS, f"{name} takes {reference.num_args} parameters"
        for i, (param, dtype) in enumerate(declared):
            assert reference.get_arg_info(i, cl.kernel_arg_info.NAME) == param, f"{name} argument {i}"
            actual = reference.get_arg_info(i, cl.kernel_arg_info.TYPE_NAME).strip()
            if dtype is None:
                assert actual.endswith("*"), f"{name} argument {i} ({param}): declared a buffer, is {actual}"
            else:
                assert actual.removeprefix("struct ") == TYPE_NAMES[np.dtype(dtype)], \
                    f"{name} argument {i} ({param}): declared {dtype}, is {actual}"


@pytest.mark.parametrize("max_buffer_bytes", [None, 32768], ids=["whole", "split"])
def test_signature_tables_match_the_kernels(device, max_buffer_bytes):
    split = max_buffer_bytes is not None
    mesh = primitives.icosphere(3)
    renderer = Renderer(scene_from_mesh(mesh), device=device, max_buffer_bytes=max_buffer_bytes)
    assert (renderer.geometry.parts() > 1) == split
    _check(renderer.context, "render.cl", renderer.device_scene.defines(), renderer.kernels, split)
    _check(renderer.context, "path.cl", renderer.device_scene.defines(), PathTracer(renderer).kernels,
           split)
    # A scene with corner colours and a texture: the -DSURFACE_DETAIL parameters too.
    colours = np.random.default_rng(1).random((len(mesh.faces), 3, 3))
    texture = Texture(np.zeros((4, 4, 3), np.uint8), "repeat", "repeat")
    detail = Scene([SceneObject(mesh.with_detail(colors=colours), Material(texture=texture))], [Light((2, 3, 4))])
    textured = Renderer(detail, device=device, max_buffer_bytes=max_buffer_bytes)
    _check(textured.context, "render.cl", textured.device_scene.defines({"SURFACE_DETAIL": None}),
           textured.kernels, split)
    _check(textured.context, "path.cl", textured.device_scene.defines({"SURFACE_DETAIL": None}),
           PathTracer(textured).kernels, split)
    for accel in ("box", "none", "sphere"):
        queries = Accel(mesh, accel=accel, device=device, max_buffer_bytes=max_buffer_bytes)
        _check(queries.context, "trace.cl", queries.device_scene.defines(), queries.kernels, split)
        # Two levels (-DACCEL_INSTANCES): the instance table too.
        shifted = np.eye(4)
        shifted[:3, 3] = (3.0, 0.0, 0.0)
        instances = Accel([mesh, (mesh, shifted)], accel=accel, device=device, max_buffer_bytes=max_buffer_bytes)
        assert "ACCEL_INSTANCES" in instances.device_scene.defines()
        _check(instances.context, "trace.cl", instances.device_scene.defines(), instances.kernels, split)


def test_the_device_builders_signatures_match(device):
    from clrt.device.build import build_defines, device_kind
    from clrt.device.build_kernels import BUILD_KERNELS
    from clrt.device.context import create_context
    from clrt.device.program import build_program
    from clrt.device.signature import typed_kernels
    context, queue = create_context(device)
    for segmented in (False, True):
        defines = build_defines("box", device_kind(queue.device), segmented=segmented)
        kernels = typed_kernels(build_program(context, "build_bvh.cl", defines), BUILD_KERNELS, defines)
        _check(context, "build_bvh.cl", defines, kernels)


def test_the_refit_signatures_match(device):
    from clrt.device.build import build_defines
    from clrt.device.context import create_context
    from clrt.device.geometry import REFIT_KERNELS
    from clrt.device.program import build_program
    from clrt.device.signature import typed_kernels
    context, _ = create_context(device)
    defines = build_defines("sphere")
    _check(context, "refit.cl", defines, typed_kernels(build_program(context, "refit.cl", defines), REFIT_KERNELS,
                                                       defines))


def test_the_crease_signatures_match(device):
    """The device's crease split and vertex normals (crease.cl, clrt.device.crease)."""
    from clrt.device.context import create_context
    from clrt.device.crease import CREASE_KERNELS, crease_defines
    from clrt.device.program import build_program
    from clrt.device.signature import typed_kernels
    context, _ = create_context(device)
    defines = crease_defines()
    _check(context, "crease.cl", defines, typed_kernels(build_program(context, "crease.cl", defines),
                                                        CREASE_KERNELS, defines))
