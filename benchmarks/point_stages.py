"""Where the wall time of a point query goes beyond its kernels:
``python -m benchmarks.point_stages [MESH] --device gpu``.

    python -m benchmarks.point_stages ../shared/meshes/bunny00.off --device gpu --repeat 7

The points are benchmarks.points' (uniform in the mesh's box grown by 10 %,
float32 numpy).  Each query is a whole call from numpy to numpy, timed as
benchmarks.points times it (median wall and kernel ms of ``--repeat`` calls
after ``--warmup``), under each variant of the input and output path, side
by side in one process:

- ``as is``: the path as the code has it;
- ``pageable results``: the results in ordinary numpy arrays (the result
  pool refused), as point queries had them before 2026-12-02;
- ``points not staged``: the points handed to the driver as they are
  (pageable memory; clrt.query.accel.RAY_STAGED_MIN_BYTES out of reach);
- ``two chunks``: the batch in two launches (``chunk_rays`` = N / 2), one
  after the other: what smaller chunks cost the kernels (each chunk orders
  its own points by cell, point_order.cl);
- ``float64 points``: the same points as float64 (numpy's default), converted
  on their way to the device.

Then one more call per query (the ``as is`` path), with every command the
queue ran: when the host enqueued it (ms after the call began) and when the
device ran it (ms after the first command was queued, device clock), so that
the device's idle gaps and the host's share show.  Timing is done here,
never in tests.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import statistics
import time
from contextlib import contextmanager

import numpy as np
import pyopencl as cl

from benchmarks.common import NON_NEGATIVE, POSITIVE, SHARED_MESHES, exit_code, parse_count

#: Each query: a name and the call on an Accel.
QUERIES = {
    "signed_distance normal": lambda accel, p: accel.signed_distance(p, sign="normal"),
    "closest_points": lambda accel, p: accel.closest_points(p),
    "winding_number": lambda accel, p: accel.winding_number(p),
}


@contextmanager
def _patched(obj, name: str, value):
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


@contextmanager
def variant(name: str, accel, points: np.ndarray):
    """The path of variant ``name`` (see the module docstring) while inside;
    gives the points to ask with."""
    from clrt.query import accel as query_accel
    if name == "pageable results":
        with _patched(accel.result_pool, "take", lambda nbytes: None):
            yield points
    elif name == "points not staged":
        with _patched(query_accel, "RAY_STAGED_MIN_BYTES", 1 << 62):
            yield points
    elif name == "two chunks":
        with _patched(accel, "chunk_rays", -(-len(points) // 2)):
            yield points
    elif name == "float64 points":
        yield points.astype(np.float64)
    else:
        yield points


VARIANTS = ("as is", "pageable results", "points not staged", "two chunks", "float64 points")


def _median(call, accel, repeat: int, warmup: int) -> tuple[float, float]:
    for _ in range(warmup):
        call()
    accel.kernel_ms()
    walls, kernels = [], []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        walls.append(1e3 * (time.perf_counter() - start))
        kernels.append(accel.kernel_ms())
    return statistics.median(walls), statistics.median(kernels)


@contextmanager
def recorded_commands(log: list):
    """Every enqueue_copy, enqueue_fill_buffer and kernel launch of pyopencl
    while inside, as (what, host seconds at enqueue, event) into ``log``."""
    def wrap(name, label):
        original = getattr(cl, name)

        def enqueue(*args, **kwargs):
            at = time.perf_counter()
            event = original(*args, **kwargs)
            log.append((label(*args), at, event))
            return event
        return _patched(cl, name, enqueue)

    def copy_label(queue, dest, src, *rest):
        if isinstance(dest, cl.Buffer) and not isinstance(src, cl.Buffer):
            return f"upload {np.asarray(src).nbytes / 1e6:.2f} MB"
        if isinstance(src, cl.Buffer) and not isinstance(dest, cl.Buffer):
            return f"download {np.asarray(dest).nbytes / 1e6:.2f} MB"
        return "copy on the device"

    with wrap("enqueue_copy", copy_label), \
            wrap("enqueue_fill_buffer", lambda *a: "fill"), \
            wrap("enqueue_nd_range_kernel", lambda queue, kernel, *a: f"kernel {kernel.function_name}"):
        yield


def timeline(call) -> list[tuple]:
    """(what, host ms at enqueue, device start ms, device end ms) of every
    command of one ``call``; device times from the first command's queueing."""
    log: list = []
    with recorded_commands(log):
        start = time.perf_counter()
        call()
        wall = 1e3 * (time.perf_counter() - start)
    for _, _, event in log:
        event.wait()
    zero = min(e.profile.queued for _, _, e in log)
    rows = [(what, 1e3 * (at - start), 1e-6 * (e.profile.start - zero), 1e-6 * (e.profile.end - zero))
            for what, at, e in log]
    return rows + [("(whole call, host)", wall, None, None)]


def run(mesh_path, count: int, device, repeat: int, warmup: int, variants) -> None:
    import clrt
    from benchmarks.points import make_points
    from clrt.scene import primitives
    from clrt.scene.sources import as_mesh

    mesh = as_mesh(mesh_path) if mesh_path else primitives.torus(1.0, 0.35, 256, 128)
    points = make_points(mesh, count)
    accel = clrt.Accel(mesh, device=device)
    print(f"{mesh_path.name if mesh_path else 'torus'}, {count:,} points, {accel.device}\n")
    print("| query | variant | wall ms | kernel ms | wall - kernel ms |")
    print("|---|---|---|---|---|")
    for query, ask in QUERIES.items():
        for name in variants:
            with variant(name, accel, points) as given:
                wall, kernel = _median(lambda: ask(accel, given), accel, repeat, warmup)
            print(f"| {query} | {name} | {wall:.2f} | {kernel:.2f} | {wall - kernel:.2f} |")
    for query, ask in QUERIES.items():
        ask(accel, points)
        print(f"\n{query}, one call as is: the queue's commands\n")
        print("| command | host enqueue ms | device start ms | device end ms | device ms |")
        print("|---|---|---|---|---|")
        for what, at, begin, end in timeline(lambda: ask(accel, points)):
            times = "| |" if begin is None else f"| {begin:.3f} | {end:.3f} | {end - begin:.3f} |"
            print(f"| {what} | {at:.3f} {times}")


def main(argv=None) -> int:
    from pathlib import Path

    p = argparse.ArgumentParser(prog="python -m benchmarks.point_stages", description=__doc__.split("\n\n")[0])
    p.add_argument("mesh", nargs="?", type=Path,
                   help=f"a mesh file (default: a generated torus; scans are in {SHARED_MESHES})")
    p.add_argument("--points", type=parse_count, default=1_000_000, help="points (default 1M)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice, the first GPU if any)")
    p.add_argument("--repeat", type=POSITIVE, default=7, help="timed calls, median reported (default 7)")
    p.add_argument("--warmup", type=NON_NEGATIVE, default=2, help="untimed calls first (default 2)")
    p.add_argument("--variants", default=",".join(VARIANTS),
                   help=f"comma-separated, of: {', '.join(VARIANTS)} (default: all)")
    args = p.parse_args(argv)
    if args.mesh is not None and not args.mesh.is_file():
        raise SystemExit(f"benchmarks.point_stages: no mesh file {args.mesh}")
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown or not variants:
        raise SystemExit(f"benchmarks.point_stages: --variants must name some of {', '.join(VARIANTS)}")
    return exit_code(run, args.mesh, args.points, args.device, args.repeat, args.warmup, variants)


if __name__ == "__main__":
    sys.exit(main())
