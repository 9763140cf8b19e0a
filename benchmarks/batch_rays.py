"""Random rays for ``python -m benchmarks.batch --rays``, made on the Dask
workers chunk by chunk.

A module of its own, so that the workers import these functions by name: run
as ``python -m``, the benchmark's own module is ``__main__``, whose functions
Dask ships by value, each task with a fresh copy of the cache below -- and
every chunk would be made anew.
"""

from __future__ import annotations

import numpy as np

RAY_SOURCES = ("numpy", "repeat")

# The chunk of rays each worker process makes once for --ray-source repeat:
# (box, chunk) -> (origins, directions), read-only.
_repeated: dict = {}


def repeated_chunk(low, span, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """One chunk of seeded random rays (origins in the box low .. low + span,
    float32; directions from a standard normal), made once per process and then
    handed out again."""
    key = (tuple(low.tolist()), tuple(span.tolist()), chunk)
    rays = _repeated.get(key)
    if rays is None:
        rng = np.random.default_rng(0)
        origins = low + rng.random((chunk, 3), dtype=np.float32) * span
        directions = rng.standard_normal((chunk, 3), dtype=np.float32)
        origins.flags.writeable = directions.flags.writeable = False
        _repeated.clear()
        rays = _repeated[key] = (origins, directions)
    return rays


def _repeated_block(low, span, chunk: int, part: int, block_info=None):
    rows = block_info[None]["chunk-shape"][0]
    return repeated_chunk(low, span, chunk)[part][:rows]


def random_rays(n: int, chunk: int, lo, hi, source: str = "numpy"):
    """(origins, directions) dask arrays of n random rays in chunks of ``chunk``,
    origins in the box lo..hi: each chunk drawn by dask's generator ("numpy"),
    or every chunk the same one, made once per worker ("repeat", see
    repeated_chunk)."""
    import dask.array as da
    low = np.asarray(lo).astype(np.float32)
    span = (np.asarray(hi, np.float64) - np.asarray(lo, np.float64)).astype(np.float32)
    if source == "numpy":
        rng = da.random.default_rng(0)
        origins = low + rng.random((n, 3), chunks=(chunk, 3), dtype=np.float32) * span
        return origins, rng.standard_normal((n, 3), chunks=(chunk, 3), dtype=np.float32)
    chunks = ((chunk,) * (n // chunk) + ((n % chunk,) if n % chunk else ()), (3,))
    return tuple(da.map_blocks(_repeated_block, low, span, chunk, part, dtype=np.float32, chunks=chunks,
                               meta=np.empty((0, 3), np.float32)) for part in (0, 1))
