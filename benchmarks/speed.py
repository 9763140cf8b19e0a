"""Primary-ray throughput on fixed cameras: ``python -m benchmarks.speed``.

The cameras are those of the speed issue, so figures can be set beside other
systems' on the same GPU: 1920x1080, one ray through each pixel centre, vertical
fov 45 degrees, up +y, tmin 0.  The kernel makes each ray and finds its
closest hit (``trace_camera`` in trace.cl), or only whether anything is hit
(``occlude_camera``).  Times are medians after warm-up: ``kernel`` from OpenCL
profiling events, ``wall`` the host clock around enqueue + finish.  After
timing, the hits are read back and checked: their count and the sum of their
distances identify the result.  ``any-hit speed-up`` is closest-hit kernel
time / any-hit kernel time: how many times faster the any-hit query runs.

``--max-buffer-mib`` lowers the largest allocation, so that the scene's buffers
are split into parts as a scene larger than the device's largest allocation
would be (split.cl): what splitting costs, measured on a small mesh.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

from clrt import layouts
from clrt.config import ACCELS, BUILDERS, MAX_LEAF_SIZE
from benchmarks.common import NON_NEGATIVE, POSITIVE, SHARED_MESHES, exit_code, int_at_least, parse_work_group, rate
from clrt.errors import ClrtError

# mesh file, eye, target (from the speed issue)
CASES = {
    "bunny00": ("bunny00.off", (0.00013, 0.000166, 1.63733), (0.00013, 0.000166, -0.000202)),
    "camel": ("camel.off", (0.539021, 0.359347, 1.796735), (0.0, 0.0, 0.0)),
}


def time_launches(queue, launch, repeat: int, warmup: int) -> tuple[float, float]:
    """Median kernel and wall ms of ``launch()`` (returns its event) over ``repeat``
    launches after ``warmup``."""
    kernel_ms, wall_ms = [], []
    for i in range(warmup + repeat):
        start = time.perf_counter()
        event = launch()
        queue.finish()
        wall = 1e3 * (time.perf_counter() - start)
        if i >= warmup:
            kernel_ms.append(1e-6 * (event.profile.end - event.profile.start))
            wall_ms.append(wall)
    return statistics.median(kernel_ms), statistics.median(wall_ms)


def run(mesh_dir: Path, cases, variants, device=None, size=(1920, 1080), repeat=20, warmup=3,
        leaf_size=4, tile=None, max_buffer_mib=None, out=sys.stdout):
    from clrt.scene.load import load_mesh
    from clrt.scene.scene import Camera
    from clrt.query import Accel

    max_buffer_bytes = None if max_buffer_mib is None else int(max_buffer_mib * 2**20)
    w, h = size
    launch = {} if tile is None else {"tile": None if tile == (0, 0) else tile}
    print("| mesh | triangles | accel | builder | buffer parts | closest: kernel ms | Mrays/s | wall ms | Mrays/s "
          "| hits | sum of t | any-hit: kernel ms | Mrays/s | any-hit speed-up |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    for name in cases:
        file, eye, target = CASES[name]
        mesh = load_mesh(mesh_dir / file)
        camera = Camera(eye, target, (0.0, 1.0, 0.0), 45.0, w, h)
        for accel_name, builder in variants:
            accel = Accel(mesh, accel=accel_name, builder=builder, leaf_size=leaf_size, device=device,
                          max_buffer_bytes=max_buffer_bytes, max_buffer_label=f"--max-buffer-mib {max_buffer_mib}")
            hit_buf = cl.Buffer(accel.context, cl.mem_flags.READ_WRITE, w * h * layouts.HIT.itemsize)
            occ_buf = cl.Buffer(accel.context, cl.mem_flags.READ_WRITE, w * h)
            closest = time_launches(accel.queue, lambda: accel.launch_camera(camera, hit_buf, **launch), repeat, warmup)
            anyhit = time_launches(accel.queue, lambda: accel.launch_camera(camera, occ_buf, occlusion=True, **launch),
                           repeat, warmup)
            hits = np.empty(w * h, layouts.HIT)
            cl.enqueue_copy(accel.queue, hits, hit_buf)
            occluded = np.empty(w * h, np.uint8)
            cl.enqueue_copy(accel.queue, occluded, occ_buf)
            hit = hits["prim"] >= 0
            if not np.array_equal(hit, occluded.astype(bool)):
                raise ClrtError(f"{name}: any-hit and closest-hit disagree on {int((hit != occluded).sum())} rays")
            mrays = lambda ms: rate(w * h / ms / 1e3)   # noqa: E731
            print(f"| {name} | {len(mesh.faces):,} | {accel_name} | {builder if accel_name != 'none' else '-'} "
                  f"| {accel.geometry.parts()} | {closest[0]:.3f} | {mrays(closest[0])} | {closest[1]:.3f} | {mrays(closest[1])} "
                  f"| {int(hit.sum()):,} | {hits['t'][hit].astype(np.float64).sum():.3f} "
                  f"| {anyhit[0]:.3f} | {mrays(anyhit[0])} | {closest[0] / anyhit[0]:.2f}x |",
                  file=out, flush=True)
    print(f"\ndevice: {accel.device}; {w}x{h}, work-group {'8x8' if tile is None else ('chosen by the driver' if tile == (0, 0) else tile)}, "
          f"warm-up {warmup}, median of {repeat}", file=out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.speed", description=__doc__.split("\n")[0])
    default_dir = SHARED_MESHES
    p.add_argument("--mesh-dir", type=Path, default=default_dir, help=f"folder of the meshes (default {default_dir})")
    p.add_argument("--case", action="append", choices=sorted(CASES), help="repeatable (default: all)")
    p.add_argument("--accel", action="append", choices=ACCELS, help="repeatable (default: box)")
    p.add_argument("--builder", action="append", choices=BUILDERS, help="repeatable (default: sah)")
    p.add_argument("--leaf-size", type=int_at_least(1, MAX_LEAF_SIZE), default=4,
                   help="most triangles per leaf (default 4)")
    p.add_argument("--tile", type=parse_work_group,
                   help="work-group as a WxH block of pixels (default 8x8; 0x0: the driver's choice)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice, the first GPU if any)")
    p.add_argument("--repeat", type=POSITIVE, default=20, help="timed frames, median reported (default 20)")
    p.add_argument("--warmup", type=NON_NEGATIVE, default=3, help="untimed frames first (default 3)")
    p.add_argument("--max-buffer-mib", type=float, help="split scene buffers larger than this (default: the device's limit)")
    args = p.parse_args(argv)
    variants = [(a, b) for a in (args.accel or ["box"]) for b in (args.builder or ["sah"])]
    return exit_code(run, args.mesh_dir, args.case or sorted(CASES), variants, args.device,
                     repeat=args.repeat, warmup=args.warmup, leaf_size=args.leaf_size, tile=args.tile,
                     max_buffer_mib=args.max_buffer_mib)


if __name__ == "__main__":
    sys.exit(main())
