"""Scale limits, measured: build time, host and device memory, frame time of
generated meshes of millions of triangles.

    python -m benchmarks.scale --triangles 1M,2M --builder paper,sah --size 640x480
    python -m benchmarks.scale --triangles 10M,20M --builder paper --size 1920x1080 --device gpu
    python -m benchmarks.scale --mesh ../shared/meshes/bunny00.off --triangles 10M --device gpu

The mesh is a torus tessellated into about N triangles (``n x n`` quads), framed
so that it fills most of the image, or with ``--mesh`` copies of that mesh on a
square grid (N rounded up to whole copies).  Per mesh size and builder: the set-up
stages (mesh generation, initialisation, acceleration build, copy to device),
the scene's device bytes (and per triangle: what bounds the largest mesh per GB,
see docs/limits.md), the process's peak host memory so far, and per image size
the median frame stages over ``--repeat`` frames after one warm-up frame, with
the number of tiles the frame was split into, and the primary-ray rate: one
closest-hit ray per pixel made and traced in one kernel (``trace_camera``, as in
``benchmarks.speed``).  ``parts``: buffers of the largest scene array (more than
one when it exceeds the device's largest allocation, see split.cl).  Prints a markdown table;
``--out FILE`` appends it to FILE as well.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import gc
import math
import resource
import statistics
import time

import numpy as np

from clrt.config import ACCELS, BUILDERS, MAX_LEAF_SIZE
from benchmarks.common import POSITIVE, int_at_least, parse_count, parse_size, rate
from clrt.errors import ClrtError


def _peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20   # kB on Linux


def instanced(mesh, count: int):
    """ceil(count / F) copies of ``mesh`` (F triangles) on a square grid in the xz plane."""
    from clrt.scene.mesh import Mesh
    copies = -(-count // len(mesh.faces))
    side = math.ceil(math.sqrt(copies))
    lo, hi = mesh.bounds
    step = 1.25 * float(max(hi[0] - lo[0], hi[2] - lo[2]))
    k = np.arange(copies)
    offsets = np.zeros((copies, 1, 3), np.float32)
    offsets[:, 0, 0], offsets[:, 0, 2] = step * (k % side), step * (k // side)
    vertices = (mesh.vertices[None] + offsets).reshape(-1, 3)
    faces = (mesh.faces[None] + (len(mesh.vertices) * k).astype(np.int32)[:, None, None]).reshape(-1, 3)
    return Mesh(vertices, faces, f"{copies} x {mesh.name}")


def _primary_rays_ms(renderer, camera, repeat: int) -> float:
    """Median kernel time of one closest-hit camera ray per pixel (trace_camera)."""
    import pyopencl as cl
    from benchmarks.speed import time_launches
    from clrt import layouts
    from clrt.query import Accel
    accel = Accel.from_renderer(renderer)
    hits = cl.Buffer(renderer.context, cl.mem_flags.READ_WRITE, camera.width * camera.height * layouts.HIT.itemsize)
    kernel_ms, _ = time_launches(accel.queue, lambda: accel.launch_camera(camera, hits), repeat, warmup=1)
    hits.release()
    return kernel_ms


def run(counts, builders, sizes, accel="box", device=None, repeat=3, leaf_size=4, out=(sys.stdout,),
        mesh_path=None):
    from clrt.renderer import Renderer
    from clrt.scene import primitives
    from clrt.scene.load import load_mesh
    from clrt.scene.scene import Camera, scene_from_mesh

    def emit(line: str = "") -> None:
        for f in out:
            print(line, file=f, flush=True)

    header = ("| triangles | builder | mesh | init | build | copy | device MiB | B/triangle | "
              "triangles per GiB | host peak GiB | resolution | tiles | ray gen | pixel colour | "
              "read back | frame wall | parts | primary rays | Mrays/s |")
    rows = []
    printed_device = False
    for count in counts:
        n = max(3, math.ceil(math.sqrt(count / 2)))
        for builder in builders:
            start = time.perf_counter()
            mesh = instanced(load_mesh(mesh_path), count) if mesh_path else primitives.torus(1.0, 0.35, n, n)
            mesh_ms = 1e3 * (time.perf_counter() - start)
            scene = scene_from_mesh(mesh)
            renderer = Renderer(scene, device=device, accel=accel, builder=builder, leaf_size=leaf_size)
            if not printed_device:
                dev = renderer.queue.device
                emit(f"device: {renderer.device}, {dev.global_mem_size / 2**30:.1f} GiB, "
                     f"{dev.max_mem_alloc_size / 2**30:.1f} GiB per buffer; accel {accel}, leaf size {leaf_size}")
                emit()
                emit(header)
                emit("|" + "---|" * (header.count("|") - 1))
                printed_device = True
            t = renderer.timings
            per_tri = renderer.device_bytes / len(mesh.faces)
            for w, h in sizes:
                if mesh_path:
                    camera = Camera.framing(scene.bounds, w, h)
                else:
                    camera = Camera((0.0, 1.9, 2.3), (0.0, 0.0, 0.0), fov=50, width=w, height=h)
                frames = []
                for i in range(1 + repeat):
                    begin = time.perf_counter()
                    frame = renderer.render(camera)
                    wall = 1e3 * (time.perf_counter() - begin)
                    if i:
                        frames.append({**{k: frame.timings[k] for k in ("ray generation", "pixel colour",
                                                                          "read back")}, "wall": wall})
                med = {k: statistics.median(f[k] for f in frames) for k in frames[0]}
                primary = _primary_rays_ms(renderer, camera, max(repeat, 5))
                row = (f"| {len(mesh.faces):,} | {builder} | {mesh_ms / 1e3:.1f} s | {t['initialisation'] / 1e3:.1f} s "
                       f"| {t['acceleration build'] / 1e3:.1f} s | {t['copy to device'] / 1e3:.1f} s "
                       f"| {renderer.device_bytes / 2**20:,.0f} | {per_tri:.0f} | {2**30 / per_tri / 1e6:.1f}M "
                       f"| {_peak_rss_gib():.1f} | {w}x{h} | {frame.tiles} | {med['ray generation']:.2f} ms "
                       f"| {med['pixel colour']:.2f} ms | {med['read back']:.2f} ms | {med['wall']:.2f} ms "
                       f"| {renderer.geometry.parts()} | {primary:.3f} ms | {rate(w * h / primary / 1e3)} |")
                rows.append(row)
                emit(row)
            del renderer, scene, mesh
            gc.collect()
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.scale", description=__doc__.split("\n\n")[0])
    p.add_argument("--triangles", type=lambda s: [parse_count(x) for x in s.split(",")], default=[10**6, 2 * 10**6],
                   help="comma-separated mesh sizes, e.g. 1M,2M,10M (default 1M,2M)")
    p.add_argument("--builder", type=lambda s: s.split(","), default=["paper", "sah"],
                   help="comma-separated builders (default paper,sah)")
    p.add_argument("--accel", default="box", choices=ACCELS, help="bounding-volume shape, or none (default box)")
    p.add_argument("--leaf-size", type=int_at_least(1, MAX_LEAF_SIZE), default=4,
                   help="most triangles per leaf (default 4)")
    p.add_argument("--size", type=parse_size, action="append", help="image size WxH, repeatable (default 640x480)")
    p.add_argument("--repeat", type=POSITIVE, default=3, help="frames timed after one warm-up (default 3)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    p.add_argument("--out", help="also append the table to this file")
    p.add_argument("--mesh", help="copies of this mesh file instead of a torus")
    args = p.parse_args(argv)
    for b in args.builder:
        if b not in BUILDERS:
            p.error(f"unknown builder {b!r}")
    outs = [sys.stdout]
    try:
        if args.out:
            outs.append(open(args.out, "a"))
        run(args.triangles, args.builder, args.size or [(640, 480)], args.accel, args.device, args.repeat,
            args.leaf_size, outs, args.mesh)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code
    finally:
        for f in outs[1:]:
            f.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
