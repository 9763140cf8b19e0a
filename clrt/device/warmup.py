"""Start the OpenCL driver while Python is still importing numpy and pyopencl.

On the H200 host a fresh ``clrt render`` spent, one after the other, about
0.4 s importing numpy and pyopencl, 0.125 s in the first platform query
(NVIDIA's driver starting) and 0.11 s creating the context.  The last two
need neither numpy nor pyopencl: :func:`start` runs them in a thread through
ctypes, which releases the GIL during a foreign call, so they overlap the
imports.  (The same in a thread through pyopencl was tried first: pyopencl
keeps the GIL during those calls, and the imports beside it stalled.)

The thread calls the very ICD loader that pyopencl links to (the wheel ships
its own), so the driver it starts is the one pyopencl then finds started.
It makes a context only for the device clrt would choose by default (the
first GPU in platform order, see context._resolve); create_context adopts it
only if the device it resolved is that very device, and releases it
otherwise.  Any failure here is silent: the ordinary path reports problems.

This module imports neither numpy nor pyopencl.
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import os
import threading

CL_DEVICE_TYPE_GPU = 1 << 2

_thread: threading.Thread | None = None
_made: dict = {}               # "device": cl_device_id, "context": cl_context (ints)
_lock = threading.Lock()


def _loader_path() -> str:
    """The ICD loader pyopencl uses: the wheel's own copy, else the system's.

    The wheel's copy reads PYOPENCL_HOME, which ``import pyopencl`` sets (to
    its package folder), and crashes without it: it is set here the same way
    first."""
    spec = importlib.util.find_spec("pyopencl")
    for folder in (spec.submodule_search_locations or []) if spec else []:
        os.environ.setdefault("PYOPENCL_HOME", os.path.abspath(folder))
        # auditwheel puts the copy in pyopencl/.libs (newer) or pyopencl.libs beside it.
        for libs_folder in (os.path.join(folder, ".libs"), folder.rstrip(os.sep) + ".libs"):
            libs = sorted(glob.glob(os.path.join(libs_folder, "libOpenCL*.so*")))
            if libs:
                return libs[0]
    return "libOpenCL.so.1"


def _declare(lib) -> None:
    """Argument types of the calls made here (undeclared, ctypes would pass
    every Python int as a C int)."""
    P, U = ctypes.c_void_p, ctypes.c_uint
    lib.clGetPlatformIDs.argtypes = [U, ctypes.POINTER(P), ctypes.POINTER(U)]
    lib.clGetDeviceIDs.argtypes = [P, ctypes.c_uint64, U, ctypes.POINTER(P), ctypes.POINTER(U)]
    lib.clCreateContext.argtypes = [P, U, ctypes.POINTER(P), P, P, ctypes.POINTER(ctypes.c_int)]
    lib.clCreateContext.restype = P
    lib.clReleaseContext.argtypes = [P]


def _ids(query, *args) -> list:
    count = ctypes.c_uint(0)
    if query(*args, 0, None, ctypes.byref(count)) != 0 or not count.value:
        return []
    ids = (ctypes.c_void_p * count.value)()
    if query(*args, count.value, ids, None) != 0:
        return []
    return [i for i in ids]


def _warm(make_context: bool) -> None:
    try:
        lib = ctypes.CDLL(_loader_path())
        _declare(lib)
        for platform in _ids(lib.clGetPlatformIDs):
            gpus = _ids(lib.clGetDeviceIDs, ctypes.c_void_p(platform), ctypes.c_uint64(CL_DEVICE_TYPE_GPU))
            if not gpus or not make_context:
                continue
            error = ctypes.c_int(0)
            device = ctypes.c_void_p(gpus[0])
            context = lib.clCreateContext(None, 1, ctypes.byref(device), None, None, ctypes.byref(error))
            if error.value == 0 and context:
                _made.update(device=gpus[0], context=context, release=lib.clReleaseContext)
            return
    except Exception:     # noqa: BLE001 -- the ordinary path reports any real problem
        return


def start(spec: str | None) -> None:
    """Warm the driver for a render on device ``spec`` (the --device value),
    where clrt would pick the first GPU: with "gpu", or with no spec (a
    PYOPENCL_CTX then may name another device: the driver is only started)."""
    global _thread
    spec = (spec or "").strip().lower()
    mode = os.environ.get("CLRT_WARMUP", "context").strip().lower()   # context | driver | off
    if spec not in ("", "gpu") or _thread is not None or mode in ("off", "0", "no"):
        return
    make_context = mode != "driver" and (spec == "gpu" or not os.environ.get("PYOPENCL_CTX", "").strip())
    _thread = start_driver_thread(threading.Thread(target=_warm, args=(make_context,), name="clrt-warmup",
                                                  daemon=True))


# Drivers start up and compile with deep call chains: their threads get a main
# thread's stack, not the smaller default of new threads.
DRIVER_STACK_BYTES = 64 << 20
_stack_lock = threading.Lock()      # (threading.stack_size is the process's: set and put back in turns)


def start_driver_thread(thread: threading.Thread) -> threading.Thread:
    """Start ``thread``, which calls into an OpenCL driver, with a driver's stack; return it."""
    with _stack_lock:
        previous = threading.stack_size(DRIVER_STACK_BYTES)
        try:
            thread.start()
        finally:
            threading.stack_size(previous)
    return thread


def wait() -> None:
    """Block until the warm-up (if any) has finished: before the first
    platform query of the ordinary path."""
    if _thread is not None:
        _thread.join()


def take_context(device_ptr: int) -> int | None:
    """The warm context's handle if it was made for ``device_ptr`` (a
    cl_device_id as an int); otherwise None, and a context made for another
    device is released."""
    wait()
    with _lock:
        context = _made.pop("context", None)
        device = _made.pop("device", None)
        release = _made.pop("release", None)
    if context is None:
        return None
    if device == device_ptr:
        return context
    release(ctypes.c_void_p(context))
    return None
