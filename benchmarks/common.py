"""What the benchmark commands share: argument types, the error exit, and the
way a benchmark starts one of its own modules in a fresh process."""

from __future__ import annotations

import argparse
import os
import sys
from contextlib import contextmanager
from pathlib import Path

from clrt.bench.common import NON_NEGATIVE, POSITIVE, int_at_least, parse_size, rate  # noqa: F401 -- clrt bench's types
from clrt.errors import ClrtError

ROOT = Path(__file__).resolve().parents[1]   # the repository: benchmarks/ and clrt/ beside each other
SHARED_MESHES = ROOT.parent / "shared" / "meshes"   # the scans beside the repository, when present


def module_command(name: str) -> list[str]:
    """``python -m benchmarks.NAME`` for a fresh process (run it with ``repo_env()``)."""
    return [sys.executable, "-m", f"benchmarks.{name}"]


def repo_env() -> dict:
    """The environment with the repository first on PYTHONPATH, so that a fresh
    process imports this checkout's ``benchmarks`` and ``clrt`` from any folder."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


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
