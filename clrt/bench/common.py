"""What the benchmark commands share: argument types and the error exit."""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager

from clrt.errors import ClrtError


def parse_size(text: str) -> tuple[int, int]:
    """argparse type for an image size 'WxH', each side in 1..MAX_IMAGE_SIDE (checked
    while parsing, so that a bad size fails before any output folder is made)."""
    from clrt.config import MAX_IMAGE_SIDE
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        w = h = 0
    if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
        raise argparse.ArgumentTypeError(f"expected WxH with each side in 1..{MAX_IMAGE_SIDE}, got {text!r}")
    return w, h


def int_at_least(lo: int, hi: int | None = None):
    """argparse type: an integer >= lo (--repeat: 1, --warmup: 0), and <= hi if given."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = lo - 1
        if value < lo or (hi is not None and value > hi):
            rule = f"an integer in {lo}..{hi}" if hi is not None else f"an integer >= {lo}"
            raise argparse.ArgumentTypeError(f"expected {rule}, got {text!r}")
        return value
    return parse


POSITIVE, NON_NEGATIVE = int_at_least(1), int_at_least(0)


def rate(value: float) -> str:
    """A rate (Mrays/s, rays/s) to three significant figures, with thousands
    separators from 1,000 up (whole numbers there) and no exponent: 0.0123,
    1.50, 32.4, 873, 12,346; "inf" and "nan" as such."""
    import math
    if not math.isfinite(value):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    # round first: 99.96 becomes 100, then gets no decimals
    digits = 2 - math.floor(math.log10(abs(float(f"{value:.3g}"))))
    return f"{value:,.{max(0, digits)}f}"


def parse_work_group(text: str) -> tuple[int, int]:
    """argparse type for a work-group as 'WxH' pixels, or '0x0' for the driver's choice."""
    return (0, 0) if text.strip().lower() == "0x0" else parse_size(text)


def parse_groups(text: str) -> list:
    """argparse type for --group: comma-separated work-group sizes (work-items,
    1..4096; the device's own limit is checked when it is known), 'driver' (the
    driver's choice) or 'default' (clrt's)."""
    groups = []
    for item in text.split(","):
        item = item.strip().lower()
        if item in ("driver", "default"):
            groups.append(item)
            continue
        try:
            size = int(item)
        except ValueError:
            size = 0
        if not 1 <= size <= 4096:
            raise argparse.ArgumentTypeError(f"expected work-group sizes in 1..4096, driver or default, "
                                             f"comma-separated; got {text!r}")
        groups.append(size)
    return groups


WALKS = ("default", "single")


def parse_walks(text: str) -> list[str]:
    """argparse type for --walks: 'default', 'single' or both, comma-separated."""
    walks = text.split(",")
    if not walks or not set(walks) <= set(WALKS):
        raise argparse.ArgumentTypeError(f"expected default and/or single, got {text!r}")
    return walks


@contextmanager
def walk(name: str):
    """Renderers and Accels made inside take walk ``name``: "default", or
    "single" -- the single-ray kernels where clrt walks packets of rays (CPU
    devices, clrt.device.geometry.RAY_PACKET_KINDS)."""
    from clrt.device import geometry
    saved = geometry.RAY_PACKET_KINDS
    if name == "single":
        geometry.RAY_PACKET_KINDS = ()
    try:
        yield
    finally:
        geometry.RAY_PACKET_KINDS = saved


def builder_label(accel: str, builder: str, walk_name: str) -> str:
    """A table's builder column: the builder ("-" without a BVH), and which walk."""
    return (builder if accel != "none" else "-") + (", single-ray walk" if walk_name == "single" else "")


def parse_count(text: str) -> int:
    """argparse type for a positive count such as 500K, 10M or 1G."""
    text = text.strip().upper()
    scale = {"K": 10**3, "M": 10**6, "G": 10**9}.get(text[-1:], 1)
    try:
        value = int(float(text.rstrip("KMG")) * scale)
    except (ValueError, OverflowError):   # OverflowError: inf
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a count such as 500K or 10M, got {text!r}")
    return value


def ray_memory(count: int, bytes_per_ray: int) -> None:
    """TooLargeError before a benchmark generates ``count`` rays that would not
    fit in the host memory available (numpy's MemoryError otherwise, part way)."""
    from clrt import checks
    checks.host_memory(count * bytes_per_ray, f"making {count:,} rays", "ask for fewer rays")


def median_wall_ms(call, repeat: int, warmup: int = 1):
    """Median wall-clock ms of ``call()`` over ``repeat`` calls after ``warmup``,
    and its last result."""
    import statistics
    import time
    times, result = [], None
    for i in range(warmup + repeat):
        start = time.perf_counter()
        result = call()
        if i >= warmup:
            times.append(1e3 * (time.perf_counter() - start))
    return statistics.median(times), result


def exit_code(run, *args, **kwargs) -> int:
    """Call ``run``; a ClrtError becomes one line on stderr and its exit code."""
    try:
        run(*args, **kwargs)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code
    return 0
