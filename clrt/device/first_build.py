"""A machine's first device builds: on the host, while a background process
makes the builder's program ready.

A device build's first call on a machine compiles the builder: on PoCL (two
cores) 2.4 s of a first ``clrt render``'s 4.3 (PoCL's compiler lock admits one
compile per process), on the H200 NVIDIA's compiler 1.1-1.6 s of a first
1080p image's 2.1-2.4 (docs/benchmarks.md).  What is compiled stays on disk
for later processes: PoCL keeps the kernels it compiled in its own cache,
clrt the binaries of programs built on other devices (clrt.device.program).

So while the builder is not ready on this machine, an "auto" build that
would run on the device runs the host's SAH builder instead (bunny00: 0.3 s)
for meshes of up to HOST_FIRST_MAX_TRIANGLES, and one background process
(``python -m clrt.device.first_build_process``) makes it ready:

- on PoCL, which compiles a kernel when it first runs it (for the grid widths
  it runs with), by making the same build on the device as the call would
  (from the corners, or a mesh's vertices and faces, which the device
  gathers), then writing a record (``$CLRT_CACHE_DIR/first-build/NAME``: the
  program's identity and the size class of the mesh, which decides the
  kernels a build launches and the widths);
- elsewhere by building the programs -- the builder's, and for a mesh's
  vertices and faces (which a GPU gathers itself) the crease split's that a
  Renderer runs after it -- whose binaries in clrt's cache are the record.

A Mesh is decided once, before its upload (clrt.device.scene's
first_builder, for Renderer and Accel): the host then gathers its corners
(and on a GPU splits its creases, as a CPU device always does).  Builds that find the record build
on the device, and so does every build once a background build has failed
(``NAME.failed``, or its lock left older than LOCK_SECONDS): as before this
rule, compiling in the call.  The trees differ; the answers do not (every
builder gives the same hits: tests/test_first_build.py) -- a two-level
scene's meshes may even be built some on the host, some on the device.  One
background build runs at a time (one lock file); a build of another kind
waits on the host for its turn.

The rule stands aside -- the device builds as before -- with
``CLRT_FIRST_BUILD=0`` (the test suite's setting, so that "auto" means one
builder there), without clrt's disk cache (``CLRT_NO_PROGRAM_CACHE``) or on
PoCL without its own (``POCL_KERNEL_CACHE=0``), for ``clrt info``'s
statistics, where the cache folder cannot be written, and where
``sys.executable`` is no Python to start (a frozen or embedding
application).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

from clrt.config import DEFAULT_LEAF_SIZE
from clrt.device.build import TAIL_THRESHOLD, default_build_program
from clrt.device.context import create_context
from clrt.device.program import cache_dir, on_pocl, program_digest
from clrt.scene.mesh import Mesh

#: The most triangles built on the host while the builder compiles: the
#: host's SAH build of 250K triangles takes about as long as the compile.
HOST_FIRST_MAX_TRIANGLES = 250_000
#: Seconds a background build may hold the lock; older, it counts as failed
#: (the process also ends itself by then: first_build_process).
LOCK_SECONDS = 600
#: Where a mesh's size changes what a build compiles on PoCL: below the
#: first, PLOC's passes never launch (the tail takes all); PoCL compiles a
#: kernel apart for grids narrower than 65535 work-items, which the node
#: kernels (2F - 1 items) pass before the triangle kernels (F).
SIZE_CLASSES = (TAIL_THRESHOLD["cpu"], 32_767, 65_534)
LOCK = "build.lock"

_names: dict[tuple, str] = {}       # record_name's, per context, volume, size and input kind
_helpers: list[subprocess.Popen] = []   # background builds this process started (threads may build at once:
_helpers_lock = threading.Lock()        # they take turns on the list)


def _folder() -> Path | None:
    programs = cache_dir()
    return None if programs is None else programs.parent / "first-build"


def _off(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in ("0", "no", "off", "false")


def applies(context: cl.Context) -> bool:
    """Does the first-build rule apply on ``context``: CLRT_FIRST_BUILD not
    off, clrt's cache (and on PoCL PoCL's) on, a Python to start?"""
    if _off("CLRT_FIRST_BUILD") or _folder() is None:
        return False
    if getattr(sys, "frozen", False) or not os.path.basename(sys.executable or "").startswith("python"):
        return False
    return not (on_pocl(context) and _off("POCL_KERNEL_CACHE"))


def size_class(num_tris: int) -> int:
    return sum(num_tris > bound for bound in SIZE_CLASSES)


def record_name(context: cl.Context, volume: str, num_tris: int, indexed: bool = False) -> str:
    """The record of the builder's program for ``num_tris`` triangles of
    ``volume`` (``indexed``: from a Mesh's vertices and faces): on PoCL the
    program's identity and the size class, elsewhere the identity alone --
    the name of its binary in clrt's cache."""
    size = size_class(num_tris) if on_pocl(context) else int(num_tris)
    key = (context.int_ptr, volume, size, num_tris > 2, bool(indexed))
    name = _names.get(key)
    if name is None:     # (the digest hashes the program's source: a few tenths of a ms)
        digest = program_digest(context, *default_build_program(context, volume, num_tris, indexed))
        name = _names[key] = f"{digest}-{size}" if on_pocl(context) else digest
    return name


def _ready(context: cl.Context, folder: Path, name: str) -> bool:
    """Is the builder ``name`` ready here (or has its background build failed)?"""
    if (folder / f"{name}.failed").exists():
        return True
    return (folder / name).exists() if on_pocl(context) else (cache_dir() / f"{name}.bin").exists()


def _input_size(corners) -> tuple[int, bool]:
    """(triangles, indexed) of a build's input: (F, 3, 3) corners, or a Mesh
    (indexed: its vertices and faces, which the device gathers); 0 for anything else."""
    if isinstance(corners, Mesh):
        return corners.num_triangles, True
    return (len(corners) if isinstance(corners, np.ndarray) else 0), False


def record(context: cl.Context, volume: str, corners) -> None:
    """Note that a device build of ``corners`` (as builds_on_host_first takes
    them) ran here, its kernels now in PoCL's cache (elsewhere the program's
    binary in clrt's is the record)."""
    if not on_pocl(context):
        return
    folder = _folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / record_name(context, volume, *_input_size(corners))).touch()
    except OSError:    # a read-only cache: the rule stands aside (builds_on_host_first)
        pass


def builds_on_host_first(corners, volume: str, device: str | None, leaf_size: int = DEFAULT_LEAF_SIZE) -> bool:
    """For an "auto" build of ``corners`` ((F, 3, 3) or a Mesh, which the
    device gathers itself) that would run on the device: true when it runs on the
    host instead, the builder not yet ready here and a background build that
    makes it ready running (started now, or by another call or process)."""
    if volume == "none":             # (no tree: nothing to build)
        return False
    num_tris, indexed = _input_size(corners)
    if not 0 < num_tris <= HOST_FIRST_MAX_TRIANGLES:
        return False
    context = create_context(device)[0]
    if not applies(context):
        return False
    _reap()
    folder, name = _folder(), record_name(context, volume, num_tris, indexed)
    if _ready(context, folder, name):
        return False
    lock = folder / LOCK
    start = (_build_command if on_pocl(context) else _compile_command)
    try:
        held_by = lock.read_text().strip()
        age = time.time() - lock.stat().st_mtime
    except OSError:
        return _start(context, folder, lock, name, start, corners, volume, leaf_size, device)
    if age < LOCK_SECONDS:
        return True                  # a background build runs (this one's or another's)
    _fail(folder, held_by, lock)     # it died without a word: its kind builds in the call from now on
    return held_by != name and _start(context, folder, lock, name, start, corners, volume, leaf_size, device)


def _build_command(folder: Path, corners, volume: str, leaf_size: int) -> tuple[list, Path]:
    """PoCL's background build: the corners (a Mesh's vertices and faces,
    .npz) in a file of the folder, the command's arguments and that file."""
    for stale in [*folder.glob("*.npy"), *folder.glob("*.npz")]:   # a background build killed before it read them
        if time.time() - stale.stat().st_mtime > LOCK_SECONDS:
            remove(stale)
    indexed = isinstance(corners, Mesh)
    fd, path = tempfile.mkstemp(dir=folder, suffix=".npz" if indexed else ".npy")
    with os.fdopen(fd, "wb") as fh:
        if indexed:
            np.savez(fh, vertices=corners.vertices, faces=corners.faces)
        else:
            np.save(fh, np.ascontiguousarray(corners, dtype=np.float32))
    return ["build", path, volume, str(leaf_size)], Path(path)


def _compile_command(folder: Path, corners, volume: str, leaf_size: int) -> tuple[list, None]:
    """The background build elsewhere: the programs compiled, no corners needed."""
    num_tris, indexed = _input_size(corners)
    return ["compile", volume, str(num_tris), "indexed" if indexed else "corners"], None


def _start(context: cl.Context, folder: Path, lock: Path, name: str, command_of, corners, volume: str,
           leaf_size: int, device: str | None) -> bool:
    """Start the background build of ``name`` (``command_of``: its arguments);
    false where it cannot start (the cache folder not writable, no process
    to start) or need not (a background build made it ready a moment ago):
    the call then builds on the device."""
    path = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        with os.fdopen(fd, "w") as fh:
            fh.write(name)
        if _ready(context, folder, name):   # (one that ended between the caller's look and the lock)
            remove(lock)
            return False
        arguments, path = command_of(folder, corners, volume, leaf_size)
        env = dict(os.environ, CLRT_FIRST_BUILD="0",           # (its own build records nothing early)
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p))   # the clrt, numpy, pyopencl of this one
        command = [sys.executable, "-m", "clrt.device.first_build_process", *arguments, device or "", name,
                   str(lock)]
        helper = subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, start_new_session=True)
        with _helpers_lock:
            _helpers.append(helper)
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
    with _helpers_lock:
        _helpers[:] = [h for h in _helpers if h.poll() is None]


def wait(timeout: float | None = None) -> list[int]:
    """Wait for the background builds this process started; their exit codes (tests, benchmarks)."""
    with _helpers_lock:
        helpers = list(_helpers)
        _helpers.clear()
    return [h.wait(timeout) for h in helpers]
