"""Mutation testing by hand-picked mutants: does the test suite notice a wrong kernel or builder?

Each mutant is one deliberate, one-token change (a comparison, a sign, an index)
in the BVH traversal, the volume tests, the triangle test, the hit rule, the
SAH sweep or the CPU walks (lane bits, wide and packet walks).  It is applied
to a temporary copy of the repository (the working tree is never touched), and
a chosen subset of the tests runs there -- fast files first, stopping at the
first failure (``pytest -x``).  A mutant is
*killed* when a test fails, and *survives* when all of them pass.

    python tools/mutate.py                 # every mutant, table on stdout
    python tools/mutate.py --list          # names and changes, nothing run
    python tools/mutate.py --only tie-rule --only t-range-tmax
    python tools/mutate.py --jobs 2        # mutants in parallel (each runs one pytest)

Exit status 1 when a mutant survives that is not marked equivalent (a change of
speed only, or one no input can tell apart: docs/mutation.md says why for each),
2 when the unmutated copy already fails its tests.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Tuple

ROOT = Path(__file__).resolve().parents[1]

KERNEL_TESTS = ("tests/test_ties.py", "tests/test_watertight.py", "tests/test_queries.py",
                "tests/test_accel.py", "tests/test_optics.py")
BOX_TESTS = ("tests/test_wide.py",) + KERNEL_TESTS
SAH_TESTS = ("tests/test_sah_reference.py", "tests/test_bvh.py", "tests/test_ties.py")
# The CPU walks (accel_wide.cl, accel_packet.cl, lanes.cl, the lane tests of
# triangle.cl and volumes.cl): test_wide.py and test_packets.py run them beside
# the binary walk, the single-ray walk and brute force on one device.
WIDE_TESTS = ("tests/test_wide.py", "tests/test_packets.py", "tests/test_watertight.py")
PACKET_TESTS = ("tests/test_packets.py", "tests/test_wide.py")


@dataclass(frozen=True)
class Mutant:
    name: str
    path: str                      # relative to the repository root
    old: str                       # must occur exactly once in the file
    new: str
    tests: Tuple[str, ...]
    equivalent: Optional[str] = None   # why no test can kill it (see docs/mutation.md)


MUTANTS = [
    # ---- traversal (accel_bvh.cl; the pop of both BVH walks is in stack.cl)
    Mutant("tie-pop", "clrt/kernels/stack.cl",
           "} while (by_distance && stack_t[*sp] > reach);",
           "} while (by_distance && stack_t[*sp] >= reach);", KERNEL_TESTS,
           equivalent="a child's entry bound is strictly below the exact distance of every "
                      "triangle inside it (padding plus the volume tests' slack), and reach lies "
                      "the relative slack beyond tmax, more than the triangle test's rounding"),
    Mutant("far-first", "clrt/kernels/accel_bvh.cl",
           "query != QUERY_ALL && t_right < t_left;", "query != QUERY_ALL && t_right > t_left;",
           KERNEL_TESTS,
           equivalent="the visiting order changes only the work done: every child that may "
                      "hold a hit within tmax is still opened, and ties go by index"),
    Mutant("stack-bottom-lost", "clrt/kernels/stack.cl",
           "if (*sp == 0)\n            return false;", "if (*sp <= 1)\n            return false;",
           KERNEL_TESTS),
    # ---- volume tests (volumes.cl).  The box mutants change volume_hit, the slab
    # test of the binary walk (GPUs); PoCL walks box trees wide (accel_wide.cl),
    # so test_wide.py, which runs both walks on one device, comes first.
    Mutant("box-enter-slack-sign", "clrt/kernels/volumes.cl",
           "*t_enter = SLACK_EARLIER(enter);   // a lower bound",
           "*t_enter = SLACK_LATER(enter);   // a lower bound", BOX_TESTS),
    Mutant("box-exit-slack-sign", "clrt/kernels/volumes.cl",
           "const float exit = SLACK_LATER(far);",
           "const float exit = SLACK_EARLIER(far);", BOX_TESTS),
    Mutant("box-enter-exit-strict", "clrt/kernels/volumes.cl",
           "callers compare it with tmax\n    return enter <= exit;",
           "callers compare it with tmax\n    return enter < exit;", BOX_TESTS,
           equivalent="enter == exit only where a ray touches a padded box in one point, and "
                      "the pad keeps every triangle strictly inside"),
    Mutant("box-tmin-ignored", "clrt/kernels/volumes.cl",
           "fmax(lo.z, tmin));", "fmax(lo.z, 0.0f));", BOX_TESTS),
    Mutant("sphere-enter-is-exit", "clrt/kernels/volumes.cl",
           "const float h = sqrt(h2);\n    const float enter = along - h - slack",
           "const float h = sqrt(h2);\n    const float enter = along + h - slack", KERNEL_TESTS),
    # ---- triangle test (triangle.cl)
    Mutant("edge-sign", "clrt/kernels/triangle.cl",
           "if ((U < 0.0f || V < 0.0f || W < 0.0f)", "if ((U < 0.0f || V < 0.0f || W <= 0.0f)",
           ("tests/test_watertight.py",) + KERNEL_TESTS),
    Mutant("t-range-tmin", "clrt/kernels/triangle.cl",
           "if (!(t > tmin && t <= tmax))", "if (!(t >= tmin && t <= tmax))", KERNEL_TESTS),
    Mutant("t-range-tmax", "clrt/kernels/triangle.cl",
           "if (!(t > tmin && t <= tmax))", "if (!(t > tmin && t < tmax))", KERNEL_TESTS),
    # ---- the hit rule (hit.cl)
    Mutant("tie-rule", "clrt/kernels/hit.cl",
           "*SPLIT_AT(g, prim_ids, slot) < *SPLIT_AT(g, prim_ids, best->prim)",
           "*SPLIT_AT(g, prim_ids, slot) > *SPLIT_AT(g, prim_ids, best->prim)", KERNEL_TESTS),
    Mutant("closest-not-strict", "clrt/kernels/hit.cl",
           "if (t < best->t || (t == best->t", "if (t <= best->t || (t == best->t", KERNEL_TESTS),
    # ---- the CPU walks (PoCL runs them for every box-tree query): the lane
    # bits, the wide walk, the packet walk, and their triangle and slab tests
    Mutant("lane-bits-avx-half", "clrt/kernels/lanes.cl",
           "return (uint)__builtin_ia32_movmskps256(as_float8(lanes));",
           "return (uint)__builtin_ia32_movmskps(as_float4(lanes.lo));", WIDE_TESTS),
    Mutant("lane-bits-portable-shift", "clrt/kernels/lanes.cl",
           "return (uint)((bytes * 0x0102040810204080UL) >> 56);",
           "return (uint)((bytes * 0x0102040810204080UL) >> 57);", WIDE_TESTS),
    Mutant("lane-mask-reversed", "clrt/kernels/lanes.cl",
           "(int8)(0, 1, 2, 3, 4, 5, 6, 7)", "(int8)(7, 6, 5, 4, 3, 2, 1, 0)", WIDE_TESTS),
    Mutant("lanes-edge-sign", "clrt/kernels/triangle.cl",
           "((U < 0.0f) | (V < 0.0f) | (W < 0.0f))", "((U < 0.0f) | (V < 0.0f) | (W <= 0.0f))",
           WIDE_TESTS),
    Mutant("lanes-t-range-tmax", "clrt/kernels/triangle.cl",
           "(t > tmin) & (t <= tmax);", "(t > tmin) & (t < tmax);", WIDE_TESTS),
    Mutant("lanes-cull-back-sign", "clrt/kernels/triangle.cl",
           "hit &= det >= 0.0f;", "hit &= det <= 0.0f;", WIDE_TESTS),
    Mutant("wide-two-far-first", "clrt/kernels/accel_wide.cl",
           "query == QUERY_CLOSEST && t1 < t2;", "query == QUERY_CLOSEST && t1 > t2;", WIDE_TESTS,
           equivalent="as far-first: the order of the two children decides only how soon tmax "
                      "shrinks; the postponed one keeps its own entry bound"),
    Mutant("wide-two-push-current", "clrt/kernels/accel_wide.cl",
           "stack[sp] = first_near ? c2 : c1;", "stack[sp] = first_near ? c1 : c2;", WIDE_TESTS),
    Mutant("wide-exit-slack-dropped", "clrt/kernels/volumes.cl",
           "const float8 exit = SLACK_LATER(far);", "const float8 exit = far;", WIDE_TESTS),
    Mutant("wide-oblique-far-shift", "clrt/kernels/volumes.cl",
           "p.far_shift = fmax(r->lo_shift, r->hi_shift);", "p.far_shift = fmin(r->lo_shift, r->hi_shift);",
           WIDE_TESTS),
    Mutant("packet-tie-rule", "clrt/kernels/accel_packet.cl",
           "((int8)(id) < best->id)", "((int8)(id) > best->id)", PACKET_TESTS),
    Mutant("packet-box-tmin-unwidened", "clrt/kernels/volumes.cl",
           "max8(near_z, SLACK_EARLIER(tmin))", "max8(near_z, tmin)", PACKET_TESTS,
           equivalent="no input found (argued, not proven): the oblique planes are true bounds "
                      "widened by volume_ray's margin, so a box whose far bound lies within the "
                      "slack below tmin holds no triangle whose computed t passes tmin"),
    Mutant("packet-entry-farthest-ray", "clrt/kernels/accel_packet.cl",
           "min_lane(select((float8)(INFINITY), enter, met))", "max_lane(select((float8)(-INFINITY), enter, met))",
           PACKET_TESTS),
    Mutant("packet-pop-other-rays", "clrt/kernels/accel_packet.cl",
           "tmax, lane_mask(open))", "tmax, lane_mask(rays))", PACKET_TESTS),
    Mutant("packet-stack-bottom-lost", "clrt/kernels/accel_packet.cl",
           "if (sp == 0)\n                return;", "if (sp <= 1)\n                return;", PACKET_TESTS),
    # ---- SAH sweep (clrt/accel/sah.py)
    Mutant("sah-n-left-off-by-one", "clrt/accel/sah.py",
           "n_left = np.minimum(slot[1:], c)", "n_left = np.minimum(slot[:-1], c)", SAH_TESTS),
    Mutant("sah-cost-right-count", "clrt/accel/sah.py",
           "cost += _area(planes[:, 1:]) * n_right", "cost += _area(planes[:, 1:]) * n_left",
           SAH_TESTS),
    Mutant("sah-binned-n-left", "clrt/accel/sah.py",
           "n_left = np.cumsum(n_in[:, :-1].T,", "n_left = np.cumsum(n_in[:, 1:].T,", SAH_TESTS),
    Mutant("sah-leaf-rule-not-strict", "clrt/accel/sah.py",
           "(forced | (split_cost < C_INTERSECT * counts))",
           "(forced | (split_cost <= C_INTERSECT * counts))", SAH_TESTS),
]


def copy_repository(dest: Path) -> None:
    """The files git knows of (tracked, and untracked but not ignored) copied to dest."""
    listed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others",
                             "--exclude-standard"], check=True, capture_output=True).stdout
    for name in sorted(set(listed.decode().split("\0")) - {""}):
        source = ROOT / name
        if source.is_file():
            target = dest / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


def apply(mutant: Mutant, root: Path) -> None:
    path = root / mutant.path
    text = path.read_text(encoding="utf-8")
    found = text.count(mutant.old)
    if found != 1:
        raise SystemExit(f"mutant {mutant.name}: {mutant.old!r} occurs {found} times in {mutant.path}")
    path.write_text(text.replace(mutant.old, mutant.new), encoding="utf-8")


_FAILED = re.compile(r"^(?:FAILED|ERROR) (.+?)(?: - .*)?$", re.MULTILINE)


def run_tests(root: Path, tests, timeout: float) -> Tuple[Optional[str], float, str]:
    """(first failing test or None, seconds, output tail) of pytest -x in ``root``."""
    env = dict(os.environ, PYTHONPATH=str(root), PYTHONDONTWRITEBYTECODE="1")
    command = [sys.executable, "-m", "pytest", "-x", "-q", "-rfE", "-p", "no:cacheprovider",
               *dict.fromkeys(tests)]
    start = time.perf_counter()
    try:
        done = subprocess.run(command, cwd=root, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"(timeout after {timeout:.0f} s)", time.perf_counter() - start, ""
    seconds = time.perf_counter() - start
    output = done.stdout + done.stderr
    if done.returncode == 0:
        return None, seconds, output[-2000:]
    failed = _FAILED.search(output)
    return (failed.group(1) if failed else f"(pytest exit {done.returncode})"), seconds, output[-2000:]


def run_mutant(mutant: Optional[Mutant], tests, timeout: float, keep: bool):
    """Copy, mutate (None: leave as is), test; the copy is removed afterwards."""
    workdir = Path(tempfile.mkdtemp(prefix=f"clrt-mutant-{mutant.name if mutant else 'none'}-"))
    try:
        copy_repository(workdir)
        if mutant is not None:
            apply(mutant, workdir)
        return run_tests(workdir, tests, timeout)
    finally:
        if keep:
            print(f"kept {workdir}", file=sys.stderr)
        else:
            shutil.rmtree(workdir, ignore_errors=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--only", action="append", metavar="NAME", help="run this mutant (repeatable)")
    parser.add_argument("--jobs", type=int, default=1, help="mutants run at once (default 1)")
    parser.add_argument("--timeout", type=float, default=1200, help="seconds per mutant's tests")
    parser.add_argument("--no-baseline", action="store_true",
                        help="skip the check that the unmutated copy passes the tests")
    parser.add_argument("--skip-equivalent", action="store_true",
                        help="leave out the mutants marked equivalent (they run every test: slow)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary copies")
    args = parser.parse_args(argv)

    chosen = MUTANTS
    if args.only:
        names = {m.name for m in MUTANTS}
        unknown = [n for n in args.only if n not in names]
        if unknown:
            parser.error(f"unknown mutant(s) {', '.join(unknown)}; see --list")
        chosen = [m for m in MUTANTS if m.name in args.only]
    if args.skip_equivalent:
        chosen = [m for m in chosen if not m.equivalent]
    if args.list:
        for m in chosen:
            note = "  [equivalent]" if m.equivalent else ""
            print(f"{m.name:26s} {m.path}: {m.old.strip()!r} -> {m.new.strip()!r}{note}")
        return 0
    for m in chosen:                                   # fail early on a stale mutant
        text = (ROOT / m.path).read_text(encoding="utf-8")
        if text.count(m.old) != 1:
            parser.error(f"mutant {m.name}: {m.old!r} occurs {text.count(m.old)} times in {m.path}")

    if not args.no_baseline:
        tests = tuple(dict.fromkeys(t for m in chosen for t in m.tests))
        failed, seconds, output = run_mutant(None, tests, args.timeout, args.keep)
        if failed:
            print(output, file=sys.stderr)
            print(f"the unmutated copy fails {failed}: fix that first", file=sys.stderr)
            return 2
        print(f"unmutated copy: {len(tests)} test files pass ({seconds:.0f} s)", file=sys.stderr)

    def one(m: Mutant):
        failed, seconds, _ = run_mutant(m, m.tests, args.timeout, args.keep)
        verdict = f"killed by {failed}" if failed else "SURVIVED"
        if not failed and m.equivalent:
            verdict += " (equivalent)"
        print(f"  {m.name}: {verdict} ({seconds:.0f} s)", file=sys.stderr, flush=True)
        return m, failed, seconds

    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        results = list(pool.map(one, chosen))

    print("| mutant | file | change | result | seconds |")
    print("|---|---|---|---|---|")
    for m, failed, seconds in results:
        old_line, new_line = next((a, b) for a, b in zip(m.old.splitlines(), m.new.splitlines()) if a != b)
        change = f"`{old_line.strip()}` -> `{new_line.strip()}`"
        change = change.replace("|", "\\|")                 # a table cell
        result = f"killed by `{failed}`" if failed else ("survived (equivalent)" if m.equivalent else "**SURVIVED**")
        print(f"| {m.name} | {Path(m.path).name} | {change} | {result} | {seconds:.0f} |")
    survivors = [m.name for m, failed, _ in results if not failed and not m.equivalent]
    equivalent = [m.name for m, failed, _ in results if not failed and m.equivalent]
    print(f"\n{len(results) - len(survivors) - len(equivalent)} killed, {len(equivalent)} equivalent "
          f"survivors, {len(survivors)} unexplained survivors{': ' + ', '.join(survivors) if survivors else ''}")
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
