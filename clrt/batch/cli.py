"""``clrt batch render SOURCE... -o DIR``: many sources and views on a Dask cluster.

``clrt/cli.py`` hands ``clrt batch ...`` over to :func:`main`.  The render
options are those of ``clrt render``, from the same definitions
(clrt/options.py).

Exit codes: 0 every job done, 2 bad input (some sources bad, the rest done),
3 device trouble, 130 interrupted (what finished is kept; run again to resume).
"""

from __future__ import annotations

import argparse
import sys

from clrt import options, output
from clrt.config import (BATCH_FIRST_TASK_RAY_SECONDS, BATCH_FIRST_TASK_SETUP, BATCH_FORMAT, BATCH_HANG_FACTOR,
                         BATCH_HANG_FLOOR, BATCH_HANG_RETRIES, BATCH_VIEWS_PER_TASK, DEVICE_ENV, MAX_VIEWS,
                         MAX_WORKERS)
from clrt.errors import DeviceError, InputError, OutputError

#: Options of ``clrt render`` that ``clrt batch render`` does not take, and why.
NOT_TAKEN = {"--output": "-o names a folder", "--aov": "images only"}


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise InputError(f"{message} (see {self.prog} --help)")


def parser() -> argparse.ArgumentParser:
    p = _Parser(prog="clrt batch", description="Batch jobs on a Dask cluster (docs/distributed.md).")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser(
        "render", help="render many sources and views into a folder",
        description="Render every SOURCE (mesh or scene file, folder of them, or glob pattern) into "
                    f"DIR/<source-stem>/view-NNNN.{BATCH_FORMAT} (or --format), with a manifest "
                    "DIR/manifest.jsonl. Finished images "
                    "are skipped when the command is run again. Without --scheduler a local cluster of "
                    "worker processes (loopback only) runs the jobs.")
    r.add_argument("sources", nargs="+", metavar="SOURCE", help="mesh or scene file, folder, or glob pattern")
    r.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created if missing)")
    r.add_argument("--format", default=BATCH_FORMAT, metavar="FMT",
                   type=options.typed(lambda v: output.format_writer(v, "--format").suffix.lstrip("."), str),
                   help=f"format of the frames: {', '.join(output.FORMAT_NAMES)} (default {BATCH_FORMAT}); exr holds "
                        f"the linear, unclamped image as float32 OpenEXR (needs {output.EXR_INSTALL_HINT}); "
                        "png with --bit-depth 16: 16-bit PNG")
    r.add_argument("--views", type=options.integer("--views", 1, MAX_VIEWS), default=1,
                   help="views per source on a turntable around the target: view i at azimuth 360*i/N "
                        "degrees, same distance, elevation and framing as the default camera (default 1)")
    where = r.add_mutually_exclusive_group()
    where.add_argument("--workers", type=options.integer("--workers", 1, MAX_WORKERS), metavar="K",
                       help="local worker processes (default: one per GPU, else one per two CPU cores)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use the workers of an existing Dask cluster, tcp://HOST:PORT or tls://HOST:PORT "
                            "(certificates from Dask's configuration, see docs/distributed.md)")
    r.add_argument("--device", type=options.device,
                   help=f"'gpu', 'cpu' or P:D; 'gpu' gives worker i the i-th GPU (default: the "
                                    f"worker's {DEVICE_ENV}, else GPUs, else the CPU)")
    r.add_argument("--task-timeout", type=options.number("--task-timeout", gt=0), metavar="SECONDS",
                   help=f"a task (up to {BATCH_VIEWS_PER_TASK} views of a source) running longer is taken as hung: "
                        f"cancelled, its worker restarted, and retried at most {BATCH_HANG_RETRIES} time(s) (default: "
                        f"{BATCH_HANG_FACTOR:g} x the median frame time per view, at least {BATCH_HANG_FLOOR:g} s; "
                        f"before any frame has finished, {BATCH_FIRST_TASK_SETUP:g} s plus "
                        f"{BATCH_FIRST_TASK_RAY_SECONDS * 1e6:g} us per camera ray of its views; this caps both)")
    r.add_argument("-f", "--force", action="store_true",
                   help="replace images and the manifest in DIR even if clrt did not write them")
    # The options of clrt render, with the same meaning.
    options.add_render_options(r)
    options.add_accel_options(r)
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar; print only the summary line")
    return p


def main(argv: list) -> int:
    """Run ``clrt batch ...``; errors are raised as ClrtError for clrt.cli to print."""
    args = parser().parse_args(options.glue_vector_values(list(argv)))
    if not args.output.strip():   # '' would be the current folder
        raise OutputError(f"-o must name a folder, got {args.output!r}")
    from clrt.batch.cluster import quiet_dask_logs, require_dask

    require_dask()
    with quiet_dask_logs():   # failures are clrt's lines, not Dask's log (clrt/batch/cluster.py)
        summary = _run(args)
    if summary is None:
        return 130
    _print_summary(summary, args.output, args.quiet)
    return summary.exit_code()


def _run(args):
    """The batch of ``args``; None when Ctrl-C stopped it."""
    from clrt.batch.cluster import connect
    from clrt.batch.engine import run
    from clrt.scene.render_setup import CAMERA_OPTIONS, SCENE_OPTIONS

    render_options = {k: getattr(args, k) for k in SCENE_OPTIONS + CAMERA_OPTIONS}
    client = connect(args.scheduler) if args.scheduler else None

    def log(line):
        if not args.quiet:
            print(line, file=sys.stderr)

    try:
        return run(args.sources, args.output, args.views, client=client, workers=args.workers,
                   device=args.device, accel=args.accel, builder=args.builder, leaf_size=args.leaf_size,
                   lights=args.light, force=args.force, progress=not args.quiet, log=log, format=args.format,
                   bit_depth=args.bit_depth, task_timeout=args.task_timeout, **render_options)
    except KeyboardInterrupt:
        print("clrt: interrupted; finished images are kept: run the same command again to resume",
              file=sys.stderr)
        return None
    except OSError as exc:   # distributed's CommClosedError and friends: the cluster went away
        reason = (str(exc).splitlines() or [""])[0] or type(exc).__name__
        raise DeviceError(f"lost the Dask cluster: {reason}; finished images are kept: "
                          "run the same command again to resume") from None
    finally:
        if client is not None:
            client.close()


def _print_summary(summary, folder: str, quiet: bool) -> None:
    """The bad sources one line each (stderr), then the totals (stdout)."""
    for line in summary.bad_sources():
        print(f"clrt: {line}", file=sys.stderr)
    rendered, skipped = summary.rendered, summary.count("skipped")
    failed = sum(summary.count(s) for s in ("bad", "device", "failed"))
    bad = len(summary.bad_sources())
    redone = summary.redone()
    why = (f" ({sum(redone.values())} re-rendered: {', '.join(f'{n} {k}' for k, n in redone.items())})"
           if redone else "")
    print(f"{rendered} frame(s) rendered{why}, {skipped} already done, {failed} not rendered "
          f"({bad} bad source(s) or error(s)); {summary.seconds:.1f} s, {summary.frames_per_second:.2f} frames/s, "
          f"{summary.workers} worker(s) -> {folder}")
    if not quiet:
        for worker, count in summary.per_worker().items():
            print(f"  {worker}: {count} frame(s)")
