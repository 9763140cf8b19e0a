"""The background process of clrt.device.pocl_warmup: one device build of
the corners it is given, as an Accel of them makes it, then the record that
the builder's kernels are in PoCL's cache.

    python -m clrt.device.pocl_warmup_process CORNERS.npy VOLUME LEAF_SIZE DEVICE NAME LOCK

It removes CORNERS.npy, and LOCK when it succeeds; when it fails, LOCK
becomes NAME.failed (no other starts for pocl_warmup.LOCK_SECONDS).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from clrt.device.pocl_warmup import remove
from clrt.device.scene import DeviceScene


def main(argv: list[str]) -> int:
    path, volume, leaf_size, device, name, lock = argv
    try:
        corners = np.load(path)
        # As an Accel of the corners does it: the build, and on CPU devices
        # the wide BVH collapsed by the builder's program too (wide_build).
        DeviceScene(corners, accel=volume, builder="device", leaf_size=int(leaf_size), device=device or None,
                    bounds=None, origin=None)
        (Path(lock).parent / name).touch()
    except Exception:      # noqa: BLE001 -- marked failed: no retry for LOCK_SECONDS
        try:
            os.replace(lock, Path(lock).with_suffix(".failed"))
        except OSError:
            pass
        return 1
    finally:
        remove(path)
    remove(lock)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
