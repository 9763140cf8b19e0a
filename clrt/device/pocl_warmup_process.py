"""The background process of clrt.device.pocl_warmup: one device build of
the corners it is given, as an Accel of them makes it, then the record that
the builder's kernels are in PoCL's cache.

    python -m clrt.device.pocl_warmup_process CORNERS.npy VOLUME LEAF_SIZE DEVICE NAME LOCK

It removes CORNERS.npy as soon as it has read it, and LOCK when it ends;
when the build fails it leaves NAME.failed (later builds of that kind
compile in their own call).  It ends itself before pocl_warmup.LOCK_SECONDS,
after which a lock left behind counts as failed.
"""

from __future__ import annotations

import faulthandler
import os
import sys
from pathlib import Path

import numpy as np

from clrt.device.pocl_warmup import LOCK_SECONDS, remove
from clrt.device.scene import DeviceScene


def main(argv: list[str]) -> int:
    path, volume, leaf_size, device, name, lock = argv
    folder = Path(lock).parent
    faulthandler.dump_traceback_later(LOCK_SECONDS - 60, exit=True)   # a hung build frees nothing else
    try:     # the call that started it comes first: its own compiles wait on no core for this one
        os.nice(10)
    except OSError:
        pass
    try:
        try:
            corners = np.load(path)
        finally:
            remove(path)
        # As an Accel of the corners: the build, and on CPU devices the wide
        # BVH collapsed by the builder's program too (wide_build).
        scene = DeviceScene(corners, accel=volume, builder="device", leaf_size=int(leaf_size),
                            device=device or None, bounds=None, origin=None)
        scene.queue.finish()
        (folder / name).touch()
        return 0
    except Exception:      # noqa: BLE001 -- its kind then builds in the call
        try:
            (folder / f"{name}.failed").touch()
        except OSError:
            pass
        return 1
    finally:
        remove(lock)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
