"""A machine's first device builds on PoCL: on the host, while a background
process compiles the builder's kernels.

On PoCL a first call with empty caches spends most of its time compiling: of
a first ``clrt render`` of bunny00 on two cores (4.3 s, against 0.8 s warm)
the device builder's program and kernels took 2.4 s, one compile after the
other (PoCL's compiler lock admits one per process; docs/benchmarks.md).
PoCL keeps what it compiles on disk, and another process finds it there.

So while the builder's kernels have not been compiled on this machine, a
build that the "auto" builder would make on a CPU device runs the host's
SAH builder instead (bunny00: 0.3 s) for meshes of up to
HOST_FIRST_MAX_TRIANGLES, and starts one background process
(``python -m clrt.device.pocl_warmup_process``) that makes the same build on the
device: PoCL's cache then holds the kernels, and clrt's a record of them
(``$CLRT_CACHE_DIR/pocl-ready/DIGEST``, the program's identity and the
mesh's size class).  Builds that find the record build on the device.  The
trees differ; the answers do not (every builder gives the same hits:
tests/test_pocl_warmup.py).

``CLRT_POCL_WARMUP=0`` turns this off (the test suite does, so that "auto"
means one builder there), as does ``CLRT_NO_PROGRAM_CACHE``.  A background
process holds a lock file (NAME.lock) while it runs, one fails leaves
NAME.failed, and either keeps others from starting for LOCK_SECONDS; its
errors go nowhere (the host build has answered the call).
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

from clrt.device.build import default_build_program
from clrt.device.context import create_context
from clrt.device.program import cache_dir, program_digest

#: The most triangles built on the host while the builder compiles: the
#: host's SAH build of 250K triangles takes about as long as the compile.
HOST_FIRST_MAX_TRIANGLES = 250_000
#: Seconds a lock file keeps others from starting a background build.
LOCK_SECONDS = 600
#: Launches of a build over this many triangles or more run grids past PoCL's
#: 16-bit kernel variants, a size class of its own in the record.
LARGE_GRID = 1 << 16

_names: dict[tuple, str] = {}       # record_name's, per context, volume and size class
_started: set[str] = set()          # records this process started a background build for
_helpers: list[subprocess.Popen] = []


def _folder() -> Path | None:
    programs = cache_dir()
    return None if programs is None else programs.parent / "pocl-ready"


def applies(context: cl.Context) -> bool:
    """Does the first-build rule apply on ``context``: a PoCL device, clrt's
    disk cache on, and CLRT_POCL_WARMUP not 0?"""
    if os.environ.get("CLRT_POCL_WARMUP", "").strip() in ("0", "no", "off") or _folder() is None:
        return False
    return all(d.platform.name == "Portable Computing Language" for d in context.devices)


def record_name(context: cl.Context, volume: str, num_tris: int) -> str:
    """The record of the builder's kernels for ``num_tris`` triangles of ``volume``."""
    size_class = "large" if num_tris >= LARGE_GRID else "small"
    key = (context.int_ptr, volume, size_class, num_tris > 2)
    name = _names.get(key)
    if name is None:     # (the digest hashes the program's source: a few tenths of a ms)
        entry, defines, kernels = default_build_program(context, volume, num_tris)
        name = _names[key] = f"{program_digest(context, entry, defines, kernels)}-{size_class}"
    return name


def ready(context: cl.Context, volume: str, num_tris: int) -> bool:
    return (_folder() / record_name(context, volume, num_tris)).exists()


def record(context: cl.Context, volume: str, num_tris: int) -> None:
    """Note that a device build of this kind ran here (its kernels are in PoCL's cache)."""
    folder = _folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / record_name(context, volume, num_tris)).touch()
    except OSError:    # a read-only cache costs the next call its host build
        pass


def builds_on_host_first(corners, volume: str, leaf_size: int, device: str | None) -> bool:
    """For an "auto" build that would run on the device: true when it should
    run on the host instead, the builder's kernels not yet compiled here --
    a background build that compiles them has then been started (or is
    running, or failed lately)."""
    if not isinstance(corners, np.ndarray) or not 0 < len(corners) <= HOST_FIRST_MAX_TRIANGLES:
        return False
    context = create_context(device)[0]
    if not applies(context) or ready(context, volume, len(corners)):
        return False
    _start(context, corners, volume, leaf_size, device)
    return True


def _start(context: cl.Context, corners: np.ndarray, volume: str, leaf_size: int, device: str | None) -> None:
    name = record_name(context, volume, len(corners))
    if name in _started:
        return
    _started.add(name)
    folder = _folder()
    lock = folder / f"{name}.lock"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not _take(lock):
            return
        fd, path = tempfile.mkstemp(dir=folder, suffix=".npy")
        with os.fdopen(fd, "wb") as fh:
            np.save(fh, np.ascontiguousarray(corners, dtype=np.float32))
    except OSError:
        return
    env = dict(os.environ)
    # The clrt this process runs, wherever it was imported from.
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
    command = [sys.executable, "-m", "clrt.device.pocl_warmup_process", path, volume, str(leaf_size), device or "",
               name, str(lock)]
    try:
        _helpers.append(subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL, start_new_session=True))
    except OSError:
        remove(path)


def _take(lock: Path) -> bool:
    """Create ``lock`` (one background build at a time, across processes);
    false while another's, or a failed one's mark, younger than
    LOCK_SECONDS, is there."""
    try:
        if time.time() - lock.with_suffix(".failed").stat().st_mtime < LOCK_SECONDS:
            return False
    except OSError:
        pass
    for _ in range(2):
        try:
            os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return True
        except FileExistsError:
            try:
                if time.time() - lock.stat().st_mtime < LOCK_SECONDS:
                    return False
                lock.unlink()
            except OSError:
                pass
    return False


def remove(path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def wait(timeout: float | None = None) -> None:
    """Wait for the background builds this process started (tests, benchmarks)."""
    for helper in _helpers:
        helper.wait(timeout)
