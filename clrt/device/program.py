"""Building OpenCL programs from the ``.cl`` sources in ``clrt/kernels``.

``#include "x"`` lines are expanded here, on the host, rather than by the
OpenCL compiler with ``-I``: the text handed to the compiler is then the whole
program, so every cache keyed on the source (ours below, pyopencl's on-disk
binary cache, the driver's) notices a change in any included file.
"""

from __future__ import annotations

import re
import warnings
from functools import lru_cache
from importlib import resources

import pyopencl as cl

from clrt.errors import KernelBuildError

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$', re.MULTILINE)


@lru_cache(maxsize=None)
def kernel_text(name: str) -> str:
    """The raw text of one file in ``clrt/kernels``."""
    return resources.files("clrt.kernels").joinpath(name).read_text(encoding="utf-8")


def expand_source(entry: str) -> str:
    """The entry file with every include expanded once (include guards not needed)."""
    seen: set[str] = set()

    def expand(name: str) -> str:
        if name in seen:
            return f"// (already included: {name})\n"
        seen.add(name)
        body = _INCLUDE.sub(lambda m: expand(m.group(1)), kernel_text(name))
        return f"// ---- {name} ----\n{body}\n"

    return expand(entry)


_programs: dict[tuple, cl.Program] = {}


def build_program(context: cl.Context, entry: str, defines: dict | None = None,
                  extra_options: tuple[str, ...] = ()) -> cl.Program:
    """Build (once per context, source and options) the program whose entry file is ``entry``.

    ``defines`` become ``-D NAME=VALUE`` options: this is how build-time choices
    (the acceleration structure, the bounding-volume shape) reach the kernels.
    Raises :class:`KernelBuildError` with the compiler log on failure.
    """
    options = [f"-D{k}" if v is None else f"-D{k}={v}" for k, v in sorted((defines or {}).items())]
    # Correctly rounded division and sqrt where the device offers them: NVIDIA's
    # default is within 2.5 ulp, and devices that round alike give alike images.
    if all(d.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT for d in context.devices):
        options.append("-cl-fp32-correctly-rounded-divide-sqrt")
    options += list(extra_options)
    source = expand_source(entry)
    key = (context.int_ptr, source, tuple(options))
    program = _programs.get(key)
    if program is None:
        try:
            with warnings.catch_warnings():
                # pyopencl turns any non-empty build log into a warning; the
                # log is only worth showing when the build fails.
                warnings.simplefilter("ignore", cl.CompilerWarning)
                program = cl.Program(context, source).build(options=options)
        except cl.RuntimeError as exc:
            raise KernelBuildError(f"OpenCL build of {entry} failed:\n{exc}") from None
        _programs[key] = program
    return program
