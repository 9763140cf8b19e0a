"""The background process of clrt.device.first_build: it makes the device
builder ready on this machine, then the record says so.

    python -m clrt.device.first_build_process build CORNERS.npy|MESH.npz VOLUME LEAF_SIZE DEVICE NAME LOCK
    python -m clrt.device.first_build_process compile VOLUME NUM_TRIS INDEXED|corners DEVICE NAME LOCK

``build`` (PoCL): one device build of the corners or of a mesh's vertices
and faces, as an Accel of them makes it (PoCL compiles each kernel as it
first runs it), then the record NAME beside LOCK; it removes its input file
as soon as it has read it.  ``compile``
(devices whose binaries clrt keeps): the builder's program for NUM_TRIS
triangles, and from a mesh's vertices and faces (``indexed``) the crease
split's programs that a Renderer runs after it; their binaries in clrt's
cache are the record.  Either removes LOCK when it ends, and when it fails
leaves NAME.failed (later builds of that kind compile in their own call).
It ends itself before first_build.LOCK_SECONDS, after which a lock left
behind counts as failed.
"""

from __future__ import annotations

import faulthandler
import os
import sys
from pathlib import Path

import numpy as np

from clrt.device.build import default_build_program
from clrt.device.context import create_context
from clrt.device.crease import crease_defines, crease_kernels
from clrt.device.first_build import LOCK_SECONDS, remove
from clrt.device.program import build_program, cache_dir
from clrt.device.scene import DeviceScene
from clrt.scene.mesh import Mesh


def build(path: str, volume: str, leaf_size: str, device: str | None) -> None:
    try:
        if path.endswith(".npz"):
            with np.load(path) as mesh:
                corners = Mesh.from_arrays(mesh["vertices"], mesh["faces"])
        else:
            corners = np.load(path)
    finally:
        remove(path)
    # As an Accel of the corners or of the mesh (gathered by the device): the
    # build, and on CPU devices the wide BVH collapsed by the builder's
    # program too (wide_build).
    scene = DeviceScene(corners, accel=volume, builder="device", leaf_size=int(leaf_size), device=device,
                        bounds=None, origin=None)
    scene.queue.finish()


def compile_programs(volume: str, num_tris: str, indexed: str, device: str | None, name: str) -> None:
    context = create_context(device)[0]
    entry, defines, kernels = default_build_program(context, volume, int(num_tris), indexed == "indexed")
    build_program(context, entry, defines, kernels=kernels)
    if not (cache_dir() / f"{name}.bin").exists():   # a driver that gives no binary: the calls compile
        raise RuntimeError("no binary kept")
    if indexed == "indexed":   # a Renderer's mesh, with and without a crease angle
        for split in (False, True):
            build_program(context, "crease.cl", crease_defines(), kernels=crease_kernels(split, True))


def main(argv: list[str]) -> int:
    mode, *arguments, device, name, lock = argv
    folder = Path(lock).parent
    faulthandler.dump_traceback_later(LOCK_SECONDS - 60, exit=True)   # a hung build frees nothing else
    try:
        try:     # the call that started it comes first: its own compiles wait on no core for this one
            os.nice(10)
        except (OSError, AttributeError):   # (no os.nice on Windows)
            pass
        if mode == "build":
            build(*arguments, device or None)
            (folder / name).touch()
        else:
            compile_programs(*arguments, device or None, name)
        return 0
    except Exception:      # noqa: BLE001 -- its kind then builds in the call
        try:
            (folder / f"{name}.failed").touch()
        except OSError:
            pass
        return 1
    finally:
        try:     # its own lock only: one taken over as stale (LOCK_SECONDS) is another build's now
            if Path(lock).read_text().strip() == name:
                remove(lock)
        except OSError:
            pass


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
