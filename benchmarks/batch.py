"""Scaling of batch rendering with the number of Dask workers.

    python -m benchmarks.batch [SOURCE ...] --workers 1,2 --views 48 --size 320x240 [--device gpu]

For each worker count, a local cluster renders every view of every source into
a fresh folder; frames/s counts the time from the first job sent to the last
result (cluster start and the workers' first program builds excluded by a
warm-up batch of one view per source on the same cluster).  Every count's
images are compared with the first count's: ``same images`` must say yes.
Without SOURCE, two generated meshes (a torus and a subdivided icosphere).
Each worker's device is printed (name and PCI bus id), so one can see that
every worker drives its own GPU.

``--breakdown`` adds where the time goes, measured in this process on every
source: the set-up a worker pays once per source (load, flatten, BVH build,
upload, context and program build), and per frame kernels, read back, the rest
of Renderer.render and PNG encoding; then the rest of a worker's time per frame
(Python, Dask, waiting for the device lock, set-up) as the difference to the
batch's own figure.
``--rays N`` adds clrt.batch.trace of N random rays (dask arrays generated on
the workers, chunks of ``--ray-chunk``): wall time and Mrays/s per worker count,
and beside it the time to make the same random arrays without tracing them.
Numpy's generators make about 10 M rays a second on a worker's one thread,
far below what a GPU traces, so ``--ray-source repeat`` has each worker make
one chunk of random rays once and hand it out for every chunk it traces: the
table then shows what tracing costs (upload, kernels, results), the way rays
coming from a fast source would be traced.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.batch_rays import RAY_SOURCES, random_rays
from benchmarks.common import exit_code, parse_count, parse_size, rate as rate_text
from clrt.config import BATCH_IMAGE_WRITERS


def _generated(folder: Path) -> list[str]:
    from clrt.scene import primitives
    paths = []
    for name, mesh in (("torus", primitives.torus(1.0, 0.35, 96, 48)), ("sphere", primitives.icosphere(4))):
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
        path = folder / f"{name}.obj"
        path.write_text("\n".join(lines) + "\n")
        paths.append(str(path))
    return paths


def run(sources, counts, views, size, device=None, samples=None, breakdown=False, rays=0, ray_chunk=1 << 22,
        ray_source="numpy", out=sys.stdout):
    from distributed import Client
    from PIL import Image

    from clrt.batch import run as batch_run
    from clrt.batch.cluster import cpu_cores, start_local_cluster
    from clrt.batch.worker import device_info

    devices, ray_rates, per_frame = {}, {}, {}

    with tempfile.TemporaryDirectory(prefix="clrt-bench-batch-") as tmp:
        tmp = Path(tmp)
        sources = list(sources) or _generated(tmp)
        w, h = size
        print(f"{len(sources)} source(s) x {views} views at {w}x{h}, {cpu_cores()} CPU core(s), "
              f"device {device or 'default'}", file=out)
        print("\n| workers | frames | seconds | frames/s | speed-up | frames per worker | same images |", file=out)
        print("|---|---|---|---|---|---|---|", file=out)
        first, base = None, None
        for count in counts:
            with start_local_cluster(count, device) as cluster, Client(cluster) as client:
                options = {"width": w, "height": h, "samples": samples, "client": client, "device": device}
                batch_run(sources, tmp / f"warm-{count}", 1, **options)
                summary = batch_run(sources, tmp / f"run-{count}", views, **options)
                devices[count] = client.run(device_info)
                if rays:
                    ray_rates[count] = _trace_rays(client, sources[0], rays, ray_chunk, ray_source)
            folder = tmp / f"run-{count}"
            images = {p.relative_to(folder): np.asarray(Image.open(p)) for p in sorted(folder.rglob("*.png"))}
            same = "-" if first is None else \
                ("yes" if images.keys() == first.keys() and all(np.array_equal(images[k], first[k]) for k in images)
                 else "NO")
            first = first if first is not None else images
            rate = summary.frames_per_second
            base = base or rate
            split = "/".join(str(n) for n in summary.per_worker().values())
            print(f"| {count} | {summary.rendered} | {summary.render_seconds:.2f} | {rate:.2f} | "
                  f"{rate / base:.2f} | {split} | {same} |", file=out)
            per_frame[count] = count * summary.render_seconds / max(summary.rendered, 1)
        print("\nworkers and their devices:", file=out)
        for count, info in devices.items():
            for address, d in sorted(info.items()):
                print(f"  {count} worker(s): {address} -> {d['device']}, PCI {d['pci']} (spec {d['spec']})", file=out)
        if breakdown:
            _breakdown(sources, views, size, samples, device, per_frame, out)
        if ray_rates:
            made = "one chunk made once per worker, repeated" if ray_source == "repeat" else "numpy's generator"
            print(f"\nrandom rays in chunks of {ray_chunk:,} ({made}):", file=out)
            print("\n| workers | rays | seconds | Mrays/s | speed-up | rays hit | generating the rays alone, s |",
                  file=out)
            print("|---|---|---|---|---|---|---|", file=out)
            first_rate = None
            for count, (seconds, hit, generate) in ray_rates.items():
                mrays = rays / seconds / 1e6
                first_rate = first_rate or mrays
                print(f"| {count} | {rays:,} | {seconds:.2f} | {rate_text(mrays)} | {mrays / first_rate:.2f} | {hit:,} "
                      f"| {generate:.2f} |", file=out, flush=True)


def _trace_rays(client, source, n: int, chunk: int, ray_source: str = "numpy") -> tuple[float, int, float]:
    """Wall seconds and hit count of clrt.batch.trace of n random rays (origins in
    the mesh's box, directions on the sphere), made chunk by chunk on the
    workers (random_rays); only the count comes back."""
    from clrt.batch import trace
    from clrt.scene.sources import as_mesh
    mesh = as_mesh(source)
    lo, hi = mesh.bounds
    origins, directions = random_rays(n, chunk, lo, hi, ray_source)
    # The same arrays made and reduced without tracing: how much of the batch's
    # time is numpy's random generators rather than clrt.
    start = time.perf_counter()
    client.compute(origins[:, 0].sum() + directions[:, 0].sum()).result()
    generate = time.perf_counter() - start
    start = time.perf_counter()
    hits = trace(mesh, origins, directions, client=client, fields=("prim",))
    hit = int(client.compute((hits.prim >= 0).sum()).result())
    return time.perf_counter() - start, hit, generate


def _breakdown(sources, views, size, samples, device, per_frame, out):
    """Where the time of a frame goes, measured here (one process) on every source:
    the set-up a worker pays once per source (load, flatten, BVH build, upload,
    context and program build), then per frame (kernels, read back, the rest of
    Renderer.render, PNG encoding); then each worker count's time per frame
    beyond that, from the batch's own figures."""
    import statistics
    import tempfile

    from clrt.output import write_image
    from clrt.renderer import Renderer
    from clrt.scene.render_setup import render_camera, render_lights, render_scene, turntable

    from clrt.device.context import create_context
    from clrt.scene.primitives import icosphere

    w, h = size
    # Once per worker: the context, and the programs every source needs (the
    # device builder's, the renderer's), built on a small sphere.
    start = time.perf_counter()
    create_context(device)
    Renderer(icosphere(1), device=device)
    once = 1e3 * (time.perf_counter() - start)
    print(f"\nwhere the time goes ({w}x{h}, one process): once per worker, the context and the builder's and "
          f"renderer's programs: {once:.0f} ms; once per source and worker, ms; per frame, the medians of up to "
          f"12 views, ms (a worker encodes its PNGs in {BATCH_IMAGE_WRITERS} threads beside its renders):\n", file=out)
    print("| source | triangles | load | flatten | BVH build | upload | programs | kernels | read back "
          "| rest of render | PNG encoding |", file=out)
    print("|---|---|---|---|---|---|---|---|---|---|---|", file=out)
    alone = []
    for source in sources:
        start = time.perf_counter()
        scene = render_scene(source, samples=samples)
        camera = render_camera(scene, width=w, height=h)
        scene.lights = render_lights(scene.bounds, camera, scene.lights)
        load = 1e3 * (time.perf_counter() - start)
        renderer = Renderer(scene, device=device)
        # A second renderer of the same scene finds the context and the program
        # built: its copy to device is the upload alone.
        second = Renderer(scene, device=device)
        upload = second.timings["copy to device"]
        del second        # (its device buffers go before the frames are timed)
        t0 = renderer.timings
        rows = []
        with tempfile.TemporaryDirectory() as folder:
            for view in range(min(views, 12)):
                cam = turntable(camera, view, views)
                begin = time.perf_counter()
                frame = renderer.render(cam)
                rendered = time.perf_counter()
                write_image(frame.image, Path(folder) / f"{view}.png", force=True)
                done = time.perf_counter()
                t = frame.timings
                rows.append((t["ray generation"] + t["pixel colour"], t["read back"], 1e3 * (rendered - begin),
                             1e3 * (done - rendered)))
        kernels, readback, frame_ms, png = (statistics.median(r[k] for r in rows) for k in range(4))
        alone.append((frame_ms, png))
        print(f"| {Path(str(source)).name} | {len(renderer.arrays.corners):,} | {load:.0f} | "
              f"{t0['initialisation']:.0f} | {t0['acceleration build']:.0f} | {upload:.0f} | "
              f"{max(t0['copy to device'] - upload, 0.0):.0f} | {kernels:.2f} | {readback:.2f} | "
              f"{frame_ms - kernels - readback:.2f} | {png:.1f} |", file=out, flush=True)
        del renderer      # before the next source's
    render = sum(r for r, _ in alone) / len(alone)
    png = sum(p for _, p in alone) / len(alone)
    print(f"\nthe sources' mean per frame: render {render:.1f} ms, PNG encoding {png:.1f} ms; a worker's time per "
          f"frame (workers x the batch's seconds / frames), and what it spends beyond the render (waiting for a "
          f"PNG writer, Dask, Python, the device lock, set-up):", file=out)
    for count, worker_ms in per_frame.items():
        print(f"  {count} worker(s): {1e3 * worker_ms:.1f} ms, {1e3 * worker_ms - render:.1f} ms beyond the render",
              file=out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.batch", description=__doc__.split("\n\n")[0])
    p.add_argument("sources", nargs="*", help="meshes or scene files (default: two generated meshes)")
    p.add_argument("--workers", default="1,2", help="worker counts, comma-separated (default 1,2)")
    p.add_argument("--views", type=int, default=48, help="views per source (default 48)")
    p.add_argument("--size", type=parse_size, default=(320, 240), help="image size WxH (default 320x240)")
    p.add_argument("--samples", type=int, help="anti-aliasing samples per side")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D")
    p.add_argument("--breakdown", action="store_true", help="also where a frame's time goes")
    p.add_argument("--rays", type=parse_count, default=0, help="also trace this many random rays, e.g. 1G")
    p.add_argument("--ray-chunk", type=parse_count, default=1 << 22, help="rays per dask chunk (default 4M)")
    p.add_argument("--ray-source", choices=RAY_SOURCES, default="numpy",
                   help="numpy: every chunk drawn anew (default); repeat: one chunk per worker, made once")
    args = p.parse_args(argv)
    counts = [int(x) for x in args.workers.split(",")]
    started = time.perf_counter()
    code = exit_code(run, args.sources, counts, args.views, args.size, args.device, args.samples, args.breakdown,
                     args.rays, args.ray_chunk, args.ray_source)
    print(f"\n({time.perf_counter() - started:.0f} s in all)")
    return code


if __name__ == "__main__":
    sys.exit(main())
