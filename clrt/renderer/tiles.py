"""How a frame is cut into launches: tile sizes, the memory fallback, Ctrl-C.

A frame is rendered in tiles -- bands of whole rows, or pieces of a row when
memory is very short -- each with its own launches.  A tile is sized so that
one launch takes about ``launch_ms`` (display watchdogs kill longer kernels;
Ctrl-C takes effect between launches) and its buffers fit the device.  When
the device runs out of memory the tiles shrink and the tile is retried; the
image is the same for every tiling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import pyopencl as cl

from clrt.device.context import is_out_of_memory


@dataclass(frozen=True)
class TileLimits:
    """The knobs of tiling, given to a Renderer when it is made."""

    launch_ms: float = 200.0                 # target kernel time of one launch (watchdogs allow 2-5 s)
    first_launch_pixels: int = 1 << 21       # the first tile, before any launch was timed (1920x1080 fits)
    max_tile_pixels: int | None = None       # cap on the pixels of a tile (None: from device memory)
    min_tile_pixels: int = 256               # a failed allocation below this is reported, not retried
    block: tuple[int, int] | None = (16, 8)  # pixels of a work-group (None: the driver's choice)


def tile_shape(x: int, y: int, width: int, height: int, budget: int, block_rows: int) -> tuple[int, int]:
    """Width and height of the tile at (x, y) of at most ``budget`` pixels: whole
    rows where the budget allows (a multiple of ``block_rows`` of them, to fill
    the launches' blocks), else a piece of one row.  Tiles go row-major through
    the image."""
    if x == 0 and budget >= width:
        rows = min(budget // width, height - y)
        if block_rows < rows < height - y:
            rows -= rows % block_rows
        return width, rows
    return min(budget, width - x), 1


def run_tiles(width: int, height: int, capacity: int, limits: TileLimits,
              render_tile: Callable[[int, int, int, int, int], float],
              release: Callable[[], None], memory_error: Callable[[BaseException, int], Exception]) -> int:
    """Render a width x height image tile by tile; return the number of tiles.

    ``capacity``: the most pixels of one tile.  ``render_tile(x, y, w, h,
    capacity)`` renders one tile into buffers sized for ``capacity`` pixels and
    returns the kernel ms of its slowest launch.  An out-of-memory error from it
    frees the per-tile buffers (``release``), quarters the capacity and retries
    the tile; below ``limits.min_tile_pixels`` it is reported as
    ``memory_error(exc, capacity)``.
    """
    budget = min(capacity, max(limits.first_launch_pixels, 1))   # pixels of the next tile
    block_rows = (limits.block or (1, 1))[1]
    x = y = tiles = 0
    ms_per_pixel = 0.0   # the most expensive tile so far: rows differ in cost (sky vs. mesh)
    while y < height:
        tw, th = tile_shape(x, y, width, height, budget, block_rows)
        try:
            slowest_ms = render_tile(x, y, tw, th, capacity)
        except (cl.Error, MemoryError) as exc:
            if not is_out_of_memory(exc):
                raise
            # Lazy allocation means buffers may fail at their first use: retry smaller.
            release()
            if capacity <= limits.min_tile_pixels:
                raise memory_error(exc, capacity) from None
            capacity = budget = max(capacity // 4, limits.min_tile_pixels)
            continue
        x += tw
        if x == width:
            x, y = 0, y + th
        tiles += 1
        # Size the next tile for launch_ms at the highest cost per pixel seen,
        # growing at most twofold: the next rows may cost more than these.
        count = tw * th
        ms_per_pixel = max(ms_per_pixel, slowest_ms / count)
        fitting = limits.launch_ms / ms_per_pixel if ms_per_pixel > 0 else capacity
        budget = int(min(max(fitting, 1), 2 * max(count, budget), capacity))
    return tiles
