"""Traversal work per ray of each builder's tree: ``python -m benchmarks.tree_counts``.

    python -m benchmarks.tree_counts --meshes bunny00,camel --builders sah,device
    python -m benchmarks.tree_counts --meshes camel --builders sah,device/reinsert=0,device --random 100K

Device-independent measures of how fast a tree traces, for comparing trees on
a machine without the GPU that decides: per tree, its SAH cost
(``stats()["sah_cost"]``) and, for the reference camera's 1920x1080 primary
rays and ``--random`` random rays (benchmarks.raysets: origins in the mesh's
box enlarged by 10 %, directions uniform; seed 0), the mean per ray of

* ``rows``: rows opened (each tests both children's boxes: the GPU walk's
  unit of work),
* ``leaves``: leaves entered, ``tris``: triangles tested,
* ``cost``: rows + tris (the SAH's units, C_TRAVERSAL = C_INTERSECT = 1),
* ``warp``: the mean over warps of 32 rays of the largest cost in the warp
  (a GPU's warp walks until its last ray is done): for primary rays the
  camera kernel's warps, 8 x 4 pixels (its work-groups are 8 x 8 pixel
  blocks), for random rays 32 rays in a row,

counted by one closest-hit walk per ray as accel_bvh.cl walks the rows (near
child first, postponed children dropped beyond the best hit) in a counting
kernel of its own (``tree_counts.cl``: float32 slab tests and the
Moller-Trumbore triangle test, so hits may differ from clrt's on a few rays
at edges; ``hit %`` shows the agreement with the first builder's tree).
Ratios are to the first builder.  Device trees are built with a GPU's choices
(treelets, the SAH top), whatever the device: ``device`` is the tree the
H200 builds.  Builders: the host builders (``sah``, ``paper``), ``device`` and
``device/NAME=N[/NAME=N...]`` with benchmarks.build's settings (``treelets``,
``treelet-min``, ``sah-top``, ``partition``, ``part-levels``, ``reinsert``, ...).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

from benchmarks.build import TUNING, tuned_variant
from benchmarks.common import NON_NEGATIVE, SHARED_MESHES, exit_code, parse_count, parse_size
from clrt.config import HOST_BUILDERS
from clrt.errors import InputError

STACK = 128            # tree_counts.cl's stack: deeper trees are refused
SOURCE = Path(__file__).with_suffix(".cl")


def device_settings(builder: str) -> dict:
    """The settings of a ``device[/NAME=N...]`` builder (benchmarks.build's
    names): build_on_device's keywords, and clrt.device.build's constants
    (upper case)."""
    try:
        return tuned_variant(builder)
    except KeyError as exc:
        raise argparse.ArgumentTypeError(f"unknown device builder setting {exc.args[0]!r} in {builder!r} "
                                         f"(choose from {', '.join(TUNING)})") from None
    except ValueError:
        raise argparse.ArgumentTypeError(f"{builder!r} needs an integer after each '='") from None


def build_tree(context, queue, corners, builder: str, leaf_size: int):
    """(rows, slotted corners (F, 3, 3) float32, stats, build ms) of one builder's tree."""
    from clrt import accel
    if builder in HOST_BUILDERS:
        start = time.perf_counter()
        built = accel.build(corners, "box", builder, leaf_size)
        ms = 1e3 * (time.perf_counter() - start)
        return built.rows, corners[built.prim_ids], built.stats(), ms
    from clrt.device import build
    settings = device_settings(builder)
    constants = {name: value for name, value in settings.items() if name.isupper()}
    saved = build.device_kind, {name: getattr(build, name) for name in constants}
    build.device_kind = lambda device: "gpu"       # the tree a GPU builds
    for name, value in constants.items():
        setattr(build, name, value)
    try:
        bvh = build.build_on_device(context, queue, corners, leaf_size=leaf_size, keep_boxes=True,
                                    **{k: v for k, v in settings.items() if k not in constants})
    finally:
        build.device_kind = saved[0]
        for name, value in saved[1].items():
            setattr(build, name, value)
    rows, prim_ids = bvh.read_back()
    stats = bvh.stats()
    bvh.release()
    return rows, corners[prim_ids], stats, bvh.build_ms


def count_walks(context, queue, rows, slotted, origins, directions, row_visits: bool = False):
    """(N, 4) int32 per ray: rows opened, leaves entered, triangles tested, slot
    hit (-1: none); with ``row_visits`` also (R,) int32, the rays that opened each row."""
    program = cl.Program(context, SOURCE.read_text()).build()
    mf = cl.mem_flags
    tris = np.zeros((len(slotted), 3, 4), np.float32)
    tris[:, :, :3] = slotted
    n = len(origins)
    buffers = [cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))
               for a in (rows, tris, np.asarray(origins, np.float32), np.asarray(directions, np.float32))]
    counts = np.empty((n, 4), np.int32)
    out = cl.Buffer(context, mf.WRITE_ONLY, counts.nbytes)
    visits = np.zeros(len(rows), np.int32) if row_visits else None
    visits_buf = cl.Buffer(context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=visits) if row_visits else None
    program.count_walk(queue, (n,), None, *buffers, np.uint32(n), out, visits_buf)
    cl.enqueue_copy(queue, counts, out)
    if row_visits:
        cl.enqueue_copy(queue, visits, visits_buf)
        visits_buf.release()
    for buffer in (*buffers, out):
        buffer.release()
    return (counts, visits) if row_visits else counts


WARP = 32
PIXEL_WARP = (4, 8)     # rows x columns of pixels in one warp of the camera kernel (8 x 8 work-groups)


def warp_cost(cost: np.ndarray, set_name: str, size) -> float:
    """Mean over warps of the largest per-ray cost in each (see WARP, PIXEL_WARP)."""
    if set_name == "primary":
        (w, h), (wh, ww) = size, PIXEL_WARP
        blocks = cost[:h // wh * wh * w].reshape(h // wh, wh, w)[:, :, :w // ww * ww]
        return float(blocks.reshape(h // wh, wh, w // ww, ww).max(axis=(1, 3)).mean())
    usable = len(cost) // WARP * WARP
    return float(cost[:usable].reshape(-1, WARP).max(axis=1).mean())


def ray_sets(mesh, name: str, size, random_count: int) -> dict:
    from benchmarks.raysets import random_rays, reference_camera
    from clrt.reference import camera_rays
    sets = {"primary": camera_rays(reference_camera(mesh, name, size))}
    if random_count:
        sets["random"] = random_rays(mesh, random_count)
    return sets


def run(mesh_dir: Path, meshes, builders, size=(1920, 1080), random_count=1_000_000, leaf_size=4, device=None,
        out=None) -> None:
    from clrt.device.context import create_context, device_label
    from clrt.scene.arrays import triangle_corners
    from clrt.scene.load import load_mesh
    out = out or sys.stdout
    context, queue = create_context(device)
    print(f"counted on {device_label(queue.device)}; leaf size {leaf_size}; per ray: rows opened, leaves, "
          f"triangles tested, cost = rows + triangles; ratios to {builders[0]}\n", file=out)
    print("| mesh | builder | build ms (this device) | SAH cost | ratio | rays | rows | leaves | tris | cost | ratio "
          "| warp | ratio | hit % |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    for name in meshes:
        mesh = load_mesh(mesh_dir / f"{name}.off")
        corners = triangle_corners(mesh)
        sets = ray_sets(mesh, name, size, random_count)
        first = {}
        for builder in builders:
            rows, slotted, stats, ms = build_tree(context, queue, corners, builder, leaf_size)
            if stats["depth"] > STACK:
                raise InputError(f"{name} {builder}: depth {stats['depth']} exceeds the counting walk's "
                                 f"stack ({STACK})")
            sah = stats["sah_cost"]
            for set_name, (origins, directions) in sets.items():
                counts = count_walks(context, queue, rows, slotted, origins, directions)
                mean = counts[:, :3].mean(axis=0)
                cost = mean[0] + mean[2]
                warp = warp_cost(counts[:, 0] + counts[:, 2], set_name, size)
                hit = counts[:, 3] >= 0
                key = (name, set_name)
                if key not in first:
                    first[key] = (sah, cost, warp, hit)
                base_sah, base_cost, base_warp, base_hit = first[key]
                print(f"| {name} | {builder} | {ms:,.1f} | {sah:.2f} | {sah / base_sah:.3f} | {set_name} "
                      f"| {mean[0]:.2f} | {mean[1]:.2f} | {mean[2]:.2f} | {cost:.2f} | {cost / base_cost:.3f} "
                      f"| {warp:.2f} | {warp / base_warp:.3f} | {100 * (hit == base_hit).mean():.3f} |", file=out,
                      flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.tree_counts", description=__doc__.split("\n")[0])
    p.add_argument("--mesh-dir", type=Path, default=SHARED_MESHES, help=f"folder of NAME.off (default {SHARED_MESHES})")
    p.add_argument("--meshes", type=lambda s: [x for x in s.split(",") if x], default=["bunny00", "camel"],
                   help="comma-separated mesh names (default bunny00,camel)")
    p.add_argument("--builders", type=lambda s: s.split(","), default=["sah", "device"],
                   help="comma-separated: sah, paper, device, device/OPTION=VALUE[/...] (default sah,device)")
    p.add_argument("--size", type=parse_size, default=(1920, 1080), help="primary rays' image (default 1920x1080)")
    p.add_argument("--random", type=lambda s: 0 if s.strip() == "0" else parse_count(s), default=1_000_000,
                   help="random rays (default 1M; 0: none)")
    p.add_argument("--leaf-size", type=NON_NEGATIVE, default=4, help="most triangles per leaf (default 4)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    args = p.parse_args(argv)
    for b in args.builders:
        if b not in HOST_BUILDERS and not b.startswith("device"):
            p.error(f"--builders: unknown builder {b!r}")
        if b.startswith("device"):
            try:
                device_settings(b)
            except argparse.ArgumentTypeError as e:
                p.error(f"--builders: {e}")
    return exit_code(run, args.mesh_dir, args.meshes, args.builders, args.size, args.random, args.leaf_size,
                     args.device)


if __name__ == "__main__":
    sys.exit(main())
