"""Building OpenCL programs from the ``.cl`` sources in ``clrt/kernels``.

``#include "x"`` lines are expanded here, on the host, rather than by the
OpenCL compiler with ``-I``: the text handed to the compiler is then the whole
program, so every cache keyed on the source (ours below, the driver's) notices
a change in any included file.

Programs are built once per context and option set, and their binaries are
kept on disk (``$CLRT_CACHE_DIR``, else ``$XDG_CACHE_HOME/clrt`` or
``~/.cache/clrt``), keyed by the expanded source, the options, the device and
its driver version: a new process loads the binary instead of compiling
(seconds on NVIDIA's compiler).  ``CLRT_NO_PROGRAM_CACHE=1`` turns the disk
cache off.  Not on PoCL, which keeps a cache of its own (keeps_binaries).
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path

import pyopencl as cl

from clrt.config import kernel_defines
from clrt.errors import KernelBuildError

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_CONDITIONAL = re.compile(r"^\s*#\s*(if|ifdef|ifndef|elif|else|endif)\b")


@lru_cache(maxsize=None)
def kernel_text(name: str) -> str:
    """The raw text of one file in ``clrt/kernels``."""
    return resources.files("clrt.kernels").joinpath(name).read_text(encoding="utf-8")


@lru_cache(maxsize=None)       # as kernel_text: the files do not change while the process runs
def expand_source(entry: str) -> str:
    """The entry file with every include expanded once (include guards not needed).

    An include inside a conditional block (other than a file's own include
    guard) is refused: expanded here it would be taken whatever the condition,
    and a file included once under a false condition would be lost to a later
    include.  Such a choice belongs in the included file (see accel.cl).
    """
    seen: set[str] = set()

    def expand(name: str) -> str:
        if name in seen:
            return f"// (already included: {name})\n"
        seen.add(name)
        out, depth = [], 0
        for number, line in enumerate(kernel_text(name).splitlines(), 1):
            conditional = _CONDITIONAL.match(line)
            if conditional:
                depth += {"if": 1, "ifdef": 1, "ifndef": 1, "endif": -1}.get(conditional.group(1), 0)
            include = _INCLUDE.match(line)
            if include is None:
                out.append(line)
                continue
            # depth 1 is the include guard that wraps every file (#ifndef CLRT_..._CL).
            guarded = name.endswith((".cl", ".h")) and depth == 1 and _has_guard(name)
            if depth > (1 if guarded else 0):
                raise KernelBuildError(f"{name}:{number}: #include inside #if is not supported "
                                       "(the host expands includes unconditionally)")
            out.append(expand(include.group(1)))
        return f"// ---- {name} ----\n" + "\n".join(out) + "\n"

    return expand(entry)


def _has_guard(name: str) -> bool:
    """Does the file open with an include guard (#ifndef X / #define X)?"""
    lines = [line.strip() for line in kernel_text(name).splitlines()
             if line.strip() and not line.strip().startswith("//")]
    return (len(lines) >= 2 and lines[0].startswith("#ifndef ")
            and lines[1].startswith("#define ") and lines[0].split()[1] == lines[1].split()[1])


# A kernel's head: __kernel, its attributes, void and its name.
_KERNEL_HEAD = re.compile(r"__kernel\s+(?:__attribute__\(\((?:[^()]|\([^()]*\))*\)\)\s*)*void\s+(\w+)\s*\(")


def keep_kernels(source: str, kernels) -> str:
    """``source`` without the kernels not named in ``kernels``: each left-out
    kernel's head and body are cut out (its helpers stay, and the compiler
    drops those that nothing calls).  Raises KernelBuildError for a named
    kernel that the source lacks."""
    return _kept(source, tuple(sorted(set(kernels))))


@functools.lru_cache(maxsize=32)
def _kept(source: str, wanted: tuple) -> str:
    """keep_kernels, once for each source and set of kernels (every Accel on a
    CPU device asks for the same cut: 20 ms of Python a time otherwise)."""
    out, position, found = [], 0, set()
    for head in _KERNEL_HEAD.finditer(source):
        if head.start() < position:
            continue
        if head.group(1) in wanted:
            found.add(head.group(1))
            continue
        out.append(source[position:head.start()])
        position = _body_end(source, head.end())
    missing = set(wanted) - found
    if missing:
        raise KernelBuildError(f"no kernel {', '.join(sorted(missing))} in the program")
    return "".join(out) + source[position:]


# What a body's end is found among: comments (skipped) and braces.
_BRACE_OR_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/|[{}]", re.S)


def _body_end(source: str, start: int) -> int:
    """Where the body of the function whose parameters open before ``start``
    ends (after its closing brace), comments skipped."""
    depth = 0
    for token in _BRACE_OR_COMMENT.finditer(source, start):
        if token.group() == "{":
            depth += 1
        elif token.group() == "}":
            depth -= 1
            if depth == 0:
                return token.end()
    raise KernelBuildError("a kernel's body does not end")


_programs: dict[tuple, cl.Program] = {}
# Programs a thread is building now (build_program): another thread that asks
# for one waits for it instead of compiling it a second time (a Renderer
# builds its program ahead, beside the tree: clrt.device.scene.build_ahead).
_building: dict[tuple, threading.Event] = {}
_building_lock = threading.Lock()
# catch_warnings swaps the process's warning filters and puts them back:
# builds in two threads at once would put back each other's (a filter left
# behind), so clrt's builds take turns at it (a Renderer's build ahead of its
# tree overlaps the tree's build, which compiles nothing on the host's first
# build of a cold call).
_warnings_lock = threading.Lock()


@dataclass(frozen=True)
class ProgramBuild:
    """One program this process built or loaded (``builds``): where a first
    call's time goes (benchmarks.cold_start)."""

    entry: str
    defines: dict            # the program's own defines, beyond config.kernel_defines()
    source_bytes: int        # of the expanded source
    kernels: int
    seconds: float           # wall time of the build (a driver with a cache of its own may have hit it)
    binary_seconds: float    # of which taking the binary for clrt's disk cache
    from_disk: bool          # loaded from clrt's disk cache


#: Every program built or loaded, in order.
builds: list[ProgramBuild] = []


def build_options(context: cl.Context, defines: dict | None = None,
                  extra_options: tuple[str, ...] = ()) -> list[str]:
    """Compiler options: ``config.kernel_defines()`` and ``defines`` as ``-D NAME=VALUE``,
    and correctly rounded division and sqrt where every device offers them."""
    merged = {**kernel_defines(), **(defines or {})}
    options = [f"-D{k}" if v is None else f"-D{k}={v}" for k, v in sorted(merged.items())]
    # NVIDIA's default is within 2.5 ulp; devices that round alike give alike images.
    if all(d.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT for d in context.devices):
        options.append("-cl-fp32-correctly-rounded-divide-sqrt")
    return options + list(extra_options)


def build_program(context: cl.Context, entry: str, defines: dict | None = None,
                  extra_options: tuple[str, ...] = (), kernels=None) -> cl.Program:
    """Build (once per context, source and options) the program whose entry file is ``entry``.

    ``defines`` become ``-D NAME=VALUE`` options: this is how build-time choices
    (the acceleration structure, the bounding-volume shape) reach the kernels.
    ``kernels``: the names of the kernels to keep (:func:`keep_kernels`), or
    None for all of them.  (The device builder keeps only those its build
    launches on CPU devices: PoCL's front end then spends about half as long
    on the program, docs/benchmarks.md.)
    Raises :class:`KernelBuildError` with the compiler log on failure.
    """
    options = build_options(context, defines, extra_options)
    source = _program_source(entry, kernels)
    key = (context.int_ptr, source, tuple(options))
    building = None
    try:
        while True:
            with _building_lock:
                program, waiting = _programs.get(key), _building.get(key)
                if program is None and waiting is None:
                    building = _building[key] = threading.Event()    # this thread builds it
            if program is not None:
                return program
            if building is not None:
                break
            waiting.wait()                   # (built there, or failed there: then tried here)
        start = time.perf_counter()
        program = _load_cached(context, source, options)
        from_disk, stored = program is not None, 0.0
        if program is None:
            program, stored = _compile(context, entry, source, options)
        # (not KERNEL_NAMES: NVIDIA's driver crashes on it for a program without kernels)
        kernels = program.get_info(cl.program_info.NUM_KERNELS)
        builds.append(ProgramBuild(entry, dict(defines or {}), len(source), kernels, time.perf_counter() - start,
                                   stored, from_disk))
        _programs[key] = program
    finally:
        if building is not None:   # (also where Ctrl-C came first: no one waits for it then)
            with _building_lock:
                del _building[key]
            building.set()
    return program


def _compile(context: cl.Context, entry: str, source: str, options: list[str]) -> tuple[cl.Program, float]:
    """The program compiled from ``source``, and the seconds its binary took to store."""
    try:
        with _warnings_lock, warnings.catch_warnings():
            # pyopencl turns any non-empty build log into a warning; the
            # log is only worth showing when the build fails.
            warnings.simplefilter("ignore", cl.CompilerWarning)
            program = cl.Program(context, source).build(options=options)
    except cl.RuntimeError as exc:
        raise KernelBuildError(f"OpenCL build of {entry} failed:\n{exc}") from None
    start = time.perf_counter()
    _store_cached(context, source, options, program)
    return program, time.perf_counter() - start


def cache_dir() -> Path | None:
    """Where program binaries are kept, or None when the disk cache is off."""
    if os.environ.get("CLRT_NO_PROGRAM_CACHE", "").strip() not in ("", "0"):
        return None
    root = os.environ.get("CLRT_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "clrt")
    return Path(root) / "programs"


def keeps_binaries(context: cl.Context) -> bool:
    """Does clrt keep the binaries of programs built on ``context`` on disk?
    Not on PoCL.  PoCL keeps a cache of its own (``$POCL_CACHE_DIR``, else
    ``~/.cache/pocl``), keyed by source and options: a program's LLVM IR when
    it is built, and each kernel compiled for a work-group size when it first
    runs with it -- only the kernels a call runs are compiled.  Asking PoCL for
    a program's binary makes it compile every kernel of the program for any
    work-group size, kernels that then run compiled anew for their own sizes
    or never run: 16 of the 17 s of build_bvh.cl's first build on 2 cores
    (``python -m benchmarks.cold_start``, docs/benchmark-log.md "Ready at once")."""
    return not on_pocl(context)


def on_pocl(context: cl.Context) -> bool:
    """Is ``context`` PoCL's (whose kernel cache is its own, keeps_binaries)?"""
    return any(d.platform.name == "Portable Computing Language" for d in context.devices)


def _digest(context: cl.Context, source: str, options: list[str]) -> str:
    """A program's identity: its expanded source, options, pyopencl and the devices and drivers."""
    h = hashlib.sha256()
    for part in (source, "\0".join(options), cl.VERSION_TEXT):
        h.update(part.encode())
        h.update(b"\1")
    for d in context.devices:
        for part in (d.platform.name, d.platform.version, d.name, d.driver_version, d.version):
            h.update(part.encode(errors="replace"))
            h.update(b"\1")
    return h.hexdigest()


def program_digest(context: cl.Context, entry: str, defines: dict | None = None, kernels=None) -> str:
    """The identity (a hex digest) of the program that build_program would
    build from these arguments: what clrt's disk cache and
    clrt.device.first_build key their files on."""
    return _digest(context, _program_source(entry, kernels), build_options(context, defines))


def _program_source(entry: str, kernels) -> str:
    """The expanded source of ``entry``, with only ``kernels`` kept (None: all)."""
    return expand_source(entry) if kernels is None else keep_kernels(expand_source(entry), kernels)


def _cache_path(context: cl.Context, source: str, options: list[str]) -> Path | None:
    folder = cache_dir()
    if folder is None or not keeps_binaries(context):
        return None
    return folder / f"{_digest(context, source, options)}.bin"


def _load_cached(context: cl.Context, source: str, options: list[str]) -> cl.Program | None:
    path = _cache_path(context, source, options)
    if path is None or len(context.devices) != 1:
        return None
    try:
        binary = path.read_bytes()
    except OSError:
        return None
    try:
        with _warnings_lock, warnings.catch_warnings():
            warnings.simplefilter("ignore", cl.CompilerWarning)
            return cl.Program(context, context.devices, [binary]).build(" ".join(options))
    except (cl.Error, cl.RuntimeError):   # a stale or damaged binary: compile instead
        return None


def _store_cached(context: cl.Context, source: str, options: list[str], program: cl.Program) -> None:
    path = _cache_path(context, source, options)
    if path is None or len(context.devices) != 1:
        return
    try:
        binary = program.get_info(cl.program_info.BINARIES)[0]
        if not binary:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(binary)
        os.replace(tmp, path)     # whole or not at all: another process may read it now
    except (OSError, cl.Error):   # a read-only home or a full disk only costs the next compile
        pass


def typed_kernel(program: cl.Program, name: str, arg_types) -> cl.Kernel:
    """Kernel ``name`` of ``program`` with its arguments' types declared: numpy
    dtypes of the scalar (by-value) parameters, None for buffers, in parameter
    order.  pyopencl then packs a whole set_args in one step (about 2 us for a
    launch's arguments instead of about 8 us per scalar), which is what keeps a
    frame's host work small.  The lists are checked against the kernels' own
    signatures in tests/test_kernel_args.py."""
    kernel = cl.Kernel(program, name)
    kernel.set_scalar_arg_dtypes(list(arg_types))
    kernel.arg_types = list(arg_types)   # kept for that test
    return kernel


def launch_size(items: int, group: int | None) -> tuple:
    """Global and local size of a 1-D launch of ``items`` work-items in groups of
    ``group`` (rounded up: the kernel must skip the work-items past the last),
    or of the driver's choice for None.  (PoCL compiles a variant of a kernel
    for each work-group size it runs, and chooses the size from the item
    count: fixed sizes keep the variants few.)"""
    return ((items,), None) if group is None else ((-(-items // group) * group,), (group,))
