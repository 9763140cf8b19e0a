"""The order a launch of point queries visits its points in (kernels/
point_order.cl: by cell of a grid over the scene, cells in Morton order), made
by the host for CPU devices (clrt.query.points chooses by device type, as
clrt.device.build chooses clrt.device.host_sort).

On a CPU device the three launches of point_order.cl are two passes of atomic
increments on one counter per cell, which PoCL runs slowly: 26 of the 240 ms
of a million closest points on homer (2-core development machine).  numpy
makes the same cells, in the same float32 steps, and numpy's stable sort of
16-bit keys is a radix sort: about half that time, with the points still in
the host's memory.  The order within a cell is then the points' own (the
device's is whatever its atomics make it); no answer depends on it, only
which work-item computes it.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from clrt.config import POINT_CELL_BITS, POINT_CELLS

#: cells fit 16 bits (POINT_CELL_BITS <= 5): numpy's stable argsort of them is one radix sort
CELL_DTYPE = np.uint16 if POINT_CELLS <= 1 << 16 else np.uint32


def _cells_by_coordinates() -> np.ndarray:
    """(POINT_CELLS,) CELL_DTYPE: point_order.cl's cell (x, y and z's bits
    interleaved, x lowest) of grid coordinates (x, y, z) at index
    ``(x << 2 * POINT_CELL_BITS) | (y << POINT_CELL_BITS) | z``."""
    side = np.arange(1 << POINT_CELL_BITS, dtype=np.uint32)
    spread = sum(((side >> b) & 1) << (3 * b) for b in range(POINT_CELL_BITS))
    x, y, z = np.meshgrid(spread, spread, spread, indexing="ij")
    return (x | (y << 1) | (z << 2)).astype(CELL_DTYPE).reshape(-1)


CELLS_BY_COORDINATES = _cells_by_coordinates()


#: points a step of point_cells: its float32 rows (384 kB) stay in the core's cache from step to step
CELL_BLOCK = 1 << 15


def point_cells(points: np.ndarray, launch: np.ndarray) -> np.ndarray:
    """(m,) CELL_DTYPE: point_cells' cell (point_order.cl) of each of the
    points ``points`` ((m, 3) or flat (3m,), any real dtype) of a launch
    (``launch``: its QueryLaunch), bit for bit: each step in float32 as the
    kernel takes it (the point converted as the upload converts it, moved by
    the launch's shift, its offset from the scene's corner divided by the
    extent, times the cells an axis), then clamped to the grid.  A point with
    a NaN coordinate (the query reports it) lands in some cell, not always
    the kernel's."""
    rows = points.reshape(-1, 3)
    shift, lo, hi = (launch[field][:3].astype(np.float32)[:, None] for field in ("shift", "scene_lo", "scene_hi"))
    extent = np.maximum(hi - lo, np.finfo(np.float32).tiny)
    cells = np.empty(len(rows), CELL_DTYPE)
    # One row an axis: each step is one contiguous pass over a block.
    coords = np.empty((3, CELL_BLOCK), np.float32)
    grid = np.empty((3, CELL_BLOCK), CELL_DTYPE)
    with np.errstate(all="ignore"):   # points that are not finite: the query kernel reports them
        for first in range(0, len(rows), CELL_BLOCK):
            block = rows[first:first + CELL_BLOCK]
            c, g = coords[:, :len(block)], grid[:, :len(block)]
            if block.dtype == np.float32:
                np.subtract(block.T, shift, out=c)
            else:
                np.copyto(c, block.T, casting="unsafe")
                c -= shift
            c -= lo
            c /= extent
            c *= np.float32(1 << POINT_CELL_BITS)
            np.clip(c, 0, (1 << POINT_CELL_BITS) - 1, out=c)   # (np.fmax and np.fmin: 3x as long)
            np.copyto(g, c, casting="unsafe")   # truncation: what convert_uint_sat does to values in [0, 31]
            g[0] <<= 2 * POINT_CELL_BITS
            g[1] <<= POINT_CELL_BITS
            g[0] |= g[1]
            g[0] |= g[2]
            g[0] &= POINT_CELLS - 1   # NaN (cast as the platform casts it) within the grid too
            np.take(CELLS_BY_COORDINATES, g[0], out=cells[first:first + len(block)])
    return cells


def cell_order(cells: np.ndarray) -> np.ndarray:
    """(m,) uint32: the point indices by cell, stably (a point's place within
    its cell is its place in the launch)."""
    return np.argsort(cells, kind="stable").astype(np.uint32)


def upload_order(queue: cl.CommandQueue, order: cl.Buffer, points: np.ndarray, launch: np.ndarray) -> cl.Event:
    """Write the visiting order of the launch's ``points`` (point_cells) where
    the query kernels read it in ``order`` (point_order.cl's POINT_ORDER: after
    the cell counts and the cells, which the host need not fill), without
    waiting; returns the copy's event (pyopencl waits for a copy whose event
    is let go: keep it until the queue has run it)."""
    m = int(launch["num_rays"])
    visit = cell_order(point_cells(points, launch))
    return cl.enqueue_copy(queue, order, visit, dst_offset=4 * (POINT_CELLS + m), is_blocking=False)
