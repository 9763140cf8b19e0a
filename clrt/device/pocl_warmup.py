"""A machine's first device builds on PoCL: on the host, while a background
process compiles the builder's kernels.

On PoCL a first call with empty caches spends most of its time compiling: of
a first ``clrt render`` of bunny00 on two cores (4.3 s, against 0.8 s warm)
the device builder's program and kernels took 2.4 s, one compile after the
other (PoCL's compiler lock admits one per process; docs/benchmarks.md).
PoCL keeps what it compiles on disk, and another process finds it there.

So while the builder's kernels have not run on this machine, a build that
the "auto" builder would make on a CPU device runs the host's SAH builder
instead (bunny00: 0.3 s) for meshes of up to HOST_FIRST_MAX_TRIANGLES, and
starts a background process (``python -m clrt.device.pocl_warmup_process``)
that makes the same build on the device as an Accel does: PoCL's cache then
holds the kernels, and clrt's a record of them (``$CLRT_CACHE_DIR/pocl-ready/
NAME``: the program's identity and the size class of the mesh, which decides
the kernels a build launches and the grid widths PoCL compiles a kernel for).
Builds that find the record build on the device, and so does every build once
a background build has failed (``NAME.failed``, or its lock left older than
LOCK_SECONDS): as before this rule, compiling in the call, which writes the
record too.  The trees differ; the answers do not (every builder gives the
same hits: tests/test_pocl_warmup.py) -- a two-level scene's meshes may even
be built some on the host, some on the device.  One background build runs at a time
(one lock file); a build of another size class or volume waits on the host
for its turn.

The rule stands aside -- the device builds as before -- with
``CLRT_POCL_WARMUP=0`` (the test suite's setting, so that "auto" means one
builder there), without clrt's disk cache (``CLRT_NO_PROGRAM_CACHE``) or
PoCL's (``POCL_KERNEL_CACHE=0``), for ``clrt info``'s statistics, where
the cache folder cannot be written, and where ``sys.executable`` is no
Python to start (a frozen or embedding application).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

from clrt.device.build import TAIL_THRESHOLD, default_build_program
from clrt.device.context import create_context
from clrt.device.program import cache_dir, on_pocl, program_digest

#: The most triangles built on the host while the builder compiles: the
#: host's SAH build of 250K triangles takes about as long as the compile.
HOST_FIRST_MAX_TRIANGLES = 250_000
#: Seconds a background build may hold the lock; older, it counts as failed
#: (the process also ends itself by then: pocl_warmup_process).
LOCK_SECONDS = 600
#: Where a mesh's size changes what a CPU build compiles: below the first,
#: PLOC's passes never launch (the tail takes all); PoCL compiles a kernel
#: apart for grids narrower than 65535 work-items, which the node kernels
#: (2F - 1 items) pass before the triangle kernels (F).
SIZE_CLASSES = (TAIL_THRESHOLD["cpu"], 32_767, 65_534)
LOCK = "build.lock"

_names: dict[tuple, str] = {}       # record_name's, per context, volume and size class
_helpers: list[subprocess.Popen] = []   # background builds this process started


def _folder() -> Path | None:
    programs = cache_dir()
    return None if programs is None else programs.parent / "pocl-ready"


def _off(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in ("0", "no", "off", "false")


def applies(context: cl.Context) -> bool:
    """Does the first-build rule apply on ``context``: a PoCL device, both
    caches on, CLRT_POCL_WARMUP not off, a Python to start?"""
    if _off("CLRT_POCL_WARMUP") or _off("POCL_KERNEL_CACHE") or _folder() is None:
        return False
    if getattr(sys, "frozen", False) or not os.path.basename(sys.executable or "").startswith("python"):
        return False
    return on_pocl(context)


def size_class(num_tris: int) -> int:
    return sum(num_tris > bound for bound in SIZE_CLASSES)


def record_name(context: cl.Context, volume: str, num_tris: int) -> str:
    """The record of the builder's kernels for ``num_tris`` triangles of ``volume``."""
    size = size_class(num_tris)
    key = (context.int_ptr, volume, size, num_tris > 2)
    name = _names.get(key)
    if name is None:     # (the digest hashes the program's source: a few tenths of a ms)
        entry, defines, kernels = default_build_program(context, volume, num_tris)
        name = _names[key] = f"{program_digest(context, entry, defines, kernels)}-{size}"
    return name


def record(context: cl.Context, volume: str, num_tris: int) -> None:
    """Note that a device build of this kind ran here (its kernels are in PoCL's cache)."""
    folder = _folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / record_name(context, volume, num_tris)).touch()
    except OSError:    # a read-only cache: the rule stands aside (builds_on_host_first)
        pass


def builds_on_host_first(corners, volume: str, leaf_size: int, device: str | None) -> bool:
    """For an "auto" build that would run on the device: true when it runs
    on the host instead, the builder's kernels not yet compiled here and a
    background build that compiles them running (started now, or by another
    call or process)."""
    if not isinstance(corners, np.ndarray) or not 0 < len(corners) <= HOST_FIRST_MAX_TRIANGLES:
        return False
    context = create_context(device)[0]
    if not applies(context):
        return False
    _reap()
    folder, name = _folder(), record_name(context, volume, len(corners))
    if (folder / name).exists() or (folder / f"{name}.failed").exists():
        return False
    lock = folder / LOCK
    try:
        held_by = lock.read_text().strip()
        age = time.time() - lock.stat().st_mtime
    except OSError:
        return _start(folder, lock, name, corners, volume, leaf_size, device)
    if age < LOCK_SECONDS:
        return True                  # a background build runs (this one's or another's)
    _fail(folder, held_by, lock)     # it died without a word: its kind builds in the call from now on
    return held_by != name and _start(folder, lock, name, corners, volume, leaf_size, device)


def _start(folder: Path, lock: Path, name: str, corners: np.ndarray, volume: str, leaf_size: int,
           device: str | None) -> bool:
    """Start the background build of ``name``; false where it cannot start
    (the cache folder not writable, another process took the lock first, no
    process to start): the call then builds on the device."""
    path = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        with os.fdopen(fd, "w") as fh:
            fh.write(name)
        for stale in folder.glob("*.npy"):       # a background build killed before it read its corners
            if time.time() - stale.stat().st_mtime > LOCK_SECONDS:
                remove(stale)
        fd, path = tempfile.mkstemp(dir=folder, suffix=".npy")
        with os.fdopen(fd, "wb") as fh:
            np.save(fh, np.ascontiguousarray(corners, dtype=np.float32))
        env = dict(os.environ, CLRT_POCL_WARMUP="0",           # (its own build records nothing early)
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p))   # the clrt, numpy, pyopencl of this one
        command = [sys.executable, "-m", "clrt.device.pocl_warmup_process", path, volume, str(leaf_size),
                   device or "", name, str(lock)]
        _helpers.append(subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL, start_new_session=True))
        return True
    except FileExistsError:          # another process started one a moment ago
        return True
    except (OSError, ValueError, subprocess.SubprocessError):
        if path is not None:
            remove(path)
        remove(lock)
        return False


def _fail(folder: Path, name: str, lock: Path) -> None:
    """Mark ``name``'s background build failed and free the lock."""
    try:
        if name:
            (folder / f"{name}.failed").touch()
        lock.unlink()
    except OSError:
        pass


def remove(path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _reap() -> None:
    """Collect the background builds of this process that have ended (no zombies)."""
    _helpers[:] = [h for h in _helpers if h.poll() is None]


def wait(timeout: float | None = None) -> list[int]:
    """Wait for the background builds this process started; their exit codes (tests, benchmarks)."""
    codes = [h.wait(timeout) for h in _helpers]
    _helpers.clear()
    return codes
