"""Per-stage times of whole frames, acceleration variants side by side.

    python -m benchmarks.frame MESH --size 200x200 --size 1920x1080 --accel none --accel box

Set-up stages (``Renderer.timings``: initialisation, acceleration build, copy
to device) are timed once per variant, as a user meets them (the first
variant's copy includes the context and program build), beside ``Renderer()``,
the wall time of the whole call.  Frame stages are medians over ``--repeat``
frames after ``--warmup`` frames (``Frame.timings``); their times come from
OpenCL profiling events (read back: the copies of the sRGB image and the tile's flag, and
any host copy after them), ``frame wall`` is the host clock around a whole
``Renderer.render`` (without reading back the hit buffer), ``wall -
stages`` what the host adds to the three, and ``wall - kernels`` what the
call takes beyond its two kernels, the read back among it (issue 38 asks for
at most 0.3 ms above the kernels at 1080p).  Every variant's image is compared with the first variant's:
``same image`` must say yes.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import itertools
import statistics
import time

import numpy as np

from clrt.config import ACCELS, BUILDERS, MAX_LEAF_SIZE
from benchmarks.common import (NON_NEGATIVE, POSITIVE, rate, int_at_least, builder_label, exit_code, parse_size, parse_walks,
                               parse_work_group, walk)

FRAME_STAGES = ("ray generation", "pixel colour", "read back")


def run(mesh_path, sizes, variants, device=None, repeat=5, warmup=1, leaf_size=4, block=None, out=sys.stdout,
        walks=("default",)):
    from clrt.renderer import Renderer, TileLimits
    from clrt.scene.default import default_scene
    from clrt.scene.load import load_mesh
    from clrt.scene.scene import Camera, default_light, scene_from_mesh

    scene = scene_from_mesh(load_mesh(mesh_path)) if mesh_path else default_scene()
    cameras = []
    for w, h in sizes:
        if mesh_path:
            cameras.append(Camera.framing(scene.bounds, w, h))
        else:
            c = scene.camera
            cameras.append(Camera(c.eye, c.target, c.up, c.fov, w, h))
    if mesh_path:
        scene.lights = [default_light(scene.bounds, cameras[0])]
    print(f"mesh: {mesh_path or 'built-in scene'}, {scene.num_triangles:,} triangles, "
          f"{len(scene.lights)} light(s); warm-up {warmup}, median of {repeat}", file=out)
    print("\n| accel | builder | resolution | build | copy to device | Renderer() | ray generation | pixel colour "
          "| read back | frame wall | wall - stages | wall - kernels | Mrays/s (primary, wall) | same image |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    first_images = {}
    rows = []
    for (accel, builder), walk_name in itertools.product(variants, walks):
        limits = TileLimits() if block is None else TileLimits(block=None if block == (0, 0) else block)
        with walk(walk_name):
            start = time.perf_counter()
            renderer = Renderer(scene, device=device, accel=accel, builder=builder, leaf_size=leaf_size,
                                limits=limits)
            renderer.queue.finish()
            made_ms = 1e3 * (time.perf_counter() - start)
        for camera in cameras:
            samples = []
            for i in range(warmup + repeat):
                start = time.perf_counter()
                frame = renderer.render(camera)
                wall = 1e3 * (time.perf_counter() - start)
                if i >= warmup:
                    stages = {s: frame.timings[s] for s in FRAME_STAGES}
                    samples.append({**stages, "frame wall": wall, "host": wall - sum(stages.values()),
                                    "above kernels": wall - stages["ray generation"] - stages["pixel colour"]})
            med = {k: statistics.median(s[k] for s in samples) for k in samples[0]}
            key = (camera.width, camera.height)
            same = np.array_equal(first_images.setdefault(key, frame.image), frame.image)
            row = {"accel": accel, "builder": builder_label(accel, builder, walk_name), "walk": walk_name,
                   "resolution": f"{camera.width}x{camera.height}",
                   "build": renderer.timings["acceleration build"],
                   "copy to device": renderer.timings["copy to device"], "made": made_ms, **med,
                   "mrays": camera.width * camera.height / med["frame wall"] / 1e3, "same": same}
            rows.append(row)
            print(f"| {row['accel']} | {row['builder']} | {row['resolution']} | {row['build']:.1f} ms "
                  f"| {row['copy to device']:.1f} ms | {made_ms:.1f} ms | "
                  + " | ".join(f"{med[s]:.3f} ms" for s in FRAME_STAGES)
                  + f" | {med['frame wall']:.3f} ms | {med['host']:.3f} ms | {med['above kernels']:.3f} ms "
                  f"| {rate(row['mrays'])} "
                  f"| {'yes' if same else 'NO'} |",
                  file=out, flush=True)
    print(f"\ndevice: {renderer.device}", file=out)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.frame", description=__doc__.split("\n")[0])
    p.add_argument("mesh", nargs="?", help="mesh file (default: the built-in scene)")
    p.add_argument("--size", type=parse_size, action="append", help="WxH, repeatable (default 200x200, 1920x1080)")
    p.add_argument("--accel", action="append", choices=ACCELS,
                   help="repeatable (default: box)")
    p.add_argument("--builder", action="append", choices=BUILDERS, help="repeatable (default: sah)")
    p.add_argument("--leaf-size", type=int_at_least(1, MAX_LEAF_SIZE), default=4,
                   help="most triangles per leaf (default 4)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D")
    p.add_argument("--repeat", type=POSITIVE, default=5, help="timed frames, median reported (default 5)")
    p.add_argument("--warmup", type=NON_NEGATIVE, default=1, help="untimed frames first (default 1)")
    p.add_argument("--walks", type=parse_walks, default=["default"],
                   help="default,single: also time the single-ray kernels where clrt walks packets of "
                        "coherent rays (CPU devices), side by side")
    p.add_argument("--block", type=parse_work_group, help="work-group as WxH pixels (default 16x8; 0x0: the driver's choice)")
    args = p.parse_args(argv)
    if args.block and args.block[0] * args.block[1] > 4096:   # no OpenCL device runs more at once
        p.error(f"--block: {args.block[0]}x{args.block[1]} is more work-items than a work-group holds "
                "(at most 4096; the device's own limit may be lower, and then the driver chooses)")
    accels, builders = args.accel or ["box"], args.builder or ["sah"]
    # No BVH, no builder: "auto" is only there to make a valid Renderer (the
    # table's builder column says "-", builder_label).
    variants = [("none", "auto")] if "none" in accels else []
    variants += [v for v in itertools.product([a for a in accels if a != "none"], builders)]
    return exit_code(run, args.mesh, args.size or [(200, 200), (1920, 1080)], variants, args.device,
                     args.repeat, args.warmup, args.leaf_size, args.block, sys.stdout, tuple(args.walks))


if __name__ == "__main__":
    sys.exit(main())
