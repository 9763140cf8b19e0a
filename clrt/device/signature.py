"""Kernel signatures, declared once for the host.

Each program's kernels are listed in one table of :class:`Param` (the query
program's in clrt/query/kernels.py, the render program's in
clrt/renderer/kernels.py); the scene's parameters that several programs share
(:data:`GEOMETRY`) are declared here.  From a table, :func:`typed_kernels`
makes the kernel objects with their argument types declared (pyopencl then
packs a launch's arguments in one step), and tests/test_kernel_args.py
checks every table against the parameters the OpenCL compiler reports --
names and types, for every program option that changes them.

A parameter is a ``__global`` buffer, or a value: a scalar or one of the
structs of clrt/layouts.py passed by value (OpenCL allows no pointers in
them, so buffers travel beside them).  Every kernel stays within
:data:`MAX_KERNEL_PARAMS` parameters in the programs clrt builds, but for
scenes larger than one allocation: under ``-DSPLIT_BUFFERS`` each scene
buffer arrives as MAX_PARTS parts (split.cl), one parameter each.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from clrt.config import MAX_PARTS
from clrt.device.program import typed_kernel
from clrt.layouts import SCENE_INFO

#: The most parameters of any kernel (tests/test_kernel_args.py holds every
#: program clrt builds to it, split scenes aside).
MAX_KERNEL_PARAMS = 12


@dataclass(frozen=True)
class Param:
    """One kernel parameter as the kernel declares it."""

    name: str
    dtype: np.dtype | None = None   # None: a __global buffer; else the value's dtype (a layouts struct or scalar)
    when: str | None = None          # the parameter exists only in programs built with this define
    split: bool = False              # a scene buffer: MAX_PARTS parts NAME0 .. NAME3 under -DSPLIT_BUFFERS


def buffer(name: str, *, when: str | None = None, split: bool = False) -> Param:
    return Param(name, None, when, split)


def value(name: str, dtype, *, when: str | None = None) -> Param:
    return Param(name, np.dtype(dtype), when)


#: The scene's geometry as every tracing kernel takes it (GEOMETRY_PARAMS in
#: geometry.cl): the triangles, the BVH rows, the slot -> triangle ids, the
#: wide BVH of CPU devices, a two-level scene's instance table, and the
#: SceneInfo values.
GEOMETRY = (buffer("tris", split=True), buffer("nodes", split=True), buffer("prim_ids", split=True),
            buffer("wide", when="BVH_WIDE"), buffer("instances", when="ACCEL_INSTANCES", split=True),
            value("scene", SCENE_INFO))


def parameters(signature, defines: dict) -> list[tuple[str, np.dtype | None]]:
    """(name, dtype or None for a buffer) of each parameter of a kernel with
    ``signature`` in a program built with ``defines``, in order."""
    out = []
    for p in signature:
        if p.when is not None and p.when not in defines:
            continue
        if p.split and "SPLIT_BUFFERS" in defines:
            out += [(f"{p.name}{k}", None) for k in range(MAX_PARTS)]
        else:
            out.append((p.name, p.dtype))
    return out


def typed_kernels(program, table: dict, defines: dict) -> "KernelTable":
    """The kernels of ``table`` (name -> signature) in ``program``, built with
    ``defines``, with their argument types declared; each keeps its parameter
    names as ``arg_names`` (for the check).  ``program``: a cl.Program, or a
    function of a kernel's name that gives the program holding it (built
    when first asked for: clrt.device.scene.DeviceScene.kernels)."""
    return KernelTable((lambda name: program) if isinstance(program, cl.Program) else program, table, defines)


class KernelTable(Mapping):
    """The kernels of a signature table by name, each made on first use: its
    kernel object and its argument types' packing code (pyopencl's invoker,
    looked up in an on-disk cache) cost about 0.3 ms a kernel on the 2-core
    development machine, and an Accel uses one or two of its program's 17."""

    def __init__(self, program_of, table: dict, defines: dict):
        self._program_of, self._table, self._defines = program_of, table, defines
        self._made: dict[str, cl.Kernel] = {}

    def __getitem__(self, name: str) -> cl.Kernel:
        kernel = self._made.get(name)
        if kernel is None:
            params = parameters(self._table[name], self._defines)
            kernel = typed_kernel(self._program_of(name), name, [dtype for _, dtype in params])
            kernel.arg_names = [p for p, _ in params]
            self._made[name] = kernel
        return kernel

    def compiled(self, name: str) -> bool:
        """Does the program hold kernel ``name`` (one built with only some of
        its kernels, clrt.device.program.keep_kernels, may not)?"""
        return name in self._program_of(name).kernel_names.split(";")

    def __iter__(self):
        return iter(self._table)

    def __len__(self) -> int:
        return len(self._table)
