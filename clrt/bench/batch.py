"""Scaling of batch rendering with the number of Dask workers:

    python -m clrt.bench.batch [SOURCE ...] --workers 1,2 --views 48 --size 320x240 [--device gpu]

For each worker count, a local cluster renders every view of every source into
a fresh folder; frames/s counts the time from the first job sent to the last
result (cluster start and the workers' first program builds excluded by a
warm-up batch of one view per source on the same cluster).  Every count's
images are compared with the first count's: ``same images`` must say yes.
Without SOURCE, two generated meshes (a torus and a subdivided icosphere).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from clrt.bench.common import exit_code, parse_size


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


def run(sources, counts, views, size, device=None, samples=None, out=sys.stdout):
    from distributed import Client
    from PIL import Image

    from clrt.batch import run as batch_run
    from clrt.batch.cluster import cpu_cores, start_local_cluster

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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m clrt.bench.batch", description=__doc__.split("\n\n")[0])
    p.add_argument("sources", nargs="*", help="meshes or scene files (default: two generated meshes)")
    p.add_argument("--workers", default="1,2", help="worker counts, comma-separated (default 1,2)")
    p.add_argument("--views", type=int, default=48, help="views per source (default 48)")
    p.add_argument("--size", type=parse_size, default=(320, 240), help="image size WxH (default 320x240)")
    p.add_argument("--samples", type=int, help="anti-aliasing samples per side")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D")
    args = p.parse_args(argv)
    counts = [int(x) for x in args.workers.split(",")]
    started = time.perf_counter()
    code = exit_code(run, args.sources, counts, args.views, args.size, args.device, args.samples)
    print(f"\n({time.perf_counter() - started:.0f} s in all)")
    return code


if __name__ == "__main__":
    sys.exit(main())
