"""Batch jobs beyond one process, on Dask distributed (``pip install 'clrt[distributed]'``).

    >>> import clrt.batch
    >>> outputs = clrt.batch.render(["meshes/*.off"], "out", views=8, width=320, height=240)
    >>> hits = clrt.batch.trace(mesh, origins, directions)     # dask arrays in, Hits of dask arrays out

``engine.py`` (many frames: planning, manifest, resume, progress), ``jobs.py``
(sources, output names, tasks), ``manifest.py`` (the output folder's record),
``worker.py`` (what runs in a worker process: its device, its caches, the
tasks), ``watch.py`` (run logs, workers that never come up, hung tasks),
``cluster.py`` (a local cluster on the loopback interface, or an existing
one), ``rays.py`` (ray queries on dask arrays), ``cli.py`` (``clrt batch``).
Guide: docs/distributed.md.  ``import clrt`` never loads this package.
"""

from clrt.batch.engine import ClusterLost, Output, Summary, render, run
from clrt.batch.rays import occluded, trace

__all__ = ["ClusterLost", "Output", "Summary", "occluded", "render", "run", "trace"]
