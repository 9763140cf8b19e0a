"""Stress the device build on a GPU, hunting the hang of
tests/test_device_build.py::test_tree_is_valid_and_volumes_conservative[crossing-box-1].

    python tools/gpu_build_stress.py [--reps 20] [--timeout 300] [--trace] [--check]

(On the H200, 2026-12-03, the suite with CLRT_TEST_DEVICE=gpu stopped at that
test on two freshly started machines and passed it on a warm one; no cause is
known yet, and on PoCL with the GPU's launches nothing hangs.)

One process per configuration (reinsertion the default / 4 / 0 iterations x treelets off /
default), each building every CORNERS mesh of tests/test_device_build.py in
the suite's order (name, then volume, then leaf size 1 and 4; then the
restructured-tree variants), --reps times.  Every build prints a line
(flush=True), so a hang shows the configuration, the round and the mesh; a
watchdog thread in the child names the build (and with --trace the kernel)
that has run longer than --stall seconds and ends the process (exit 3).

--trace  waits for every launch before the next (queue.finish) and remembers
         its name: the watchdog then names the kernel that never finished.
--check  also reads the BuildNode tree back after ploc_top, every refit and
         the treelets (a valid tree: parent links, counts, heights), and the
         treelet order after treelet_order (a permutation, lowest first, each
         listed child before its parent); implies --trace.
--cpu-as-gpu  run the GPU driver's launches on a CPU device (PoCL), to test
         this script.
--config R,T  only that configuration (R: reinsert iterations, T: treelet
         leaves, 'default' for the device type's).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))   # the repository
CONFIGS = [("default", "default"), ("4", "default"), ("0", "default"), ("4", "0"), ("0", "0")]


def parent(args) -> int:
    configs = [tuple(args.config.split(","))] if args.config else CONFIGS
    worst = 0
    for reinsert, treelets in configs:
        command = [sys.executable, os.path.abspath(__file__), "--child", "--config", f"{reinsert},{treelets}",
                   "--reps", str(args.reps), "--stall", str(args.stall)]
        command += ["--trace"] * args.trace + ["--check"] * args.check + ["--cpu-as-gpu"] * args.cpu_as_gpu
        print(f"=== config reinsert_iterations={reinsert} treelet_leaves={treelets}", flush=True)
        start = time.time()
        try:
            rc = subprocess.run(command, timeout=args.timeout, cwd=HERE).returncode
        except subprocess.TimeoutExpired:
            rc = "timeout"
        print(f"=== config reinsert_iterations={reinsert} treelet_leaves={treelets}: rc={rc} "
              f"({time.time() - start:.1f} s)", flush=True)
        worst = worst or (rc != 0)
    return int(worst)


def child(args) -> int:
    sys.path.insert(0, os.path.join(HERE, "tests"))
    import numpy as np
    import pyopencl as cl
    from clrt import layouts
    from clrt.config import VOLUMES
    from clrt.device import build
    from clrt.device.build import STATE, build_on_device
    from clrt.device.build_kernels import workspace
    from clrt.device.context import create_context
    from test_device_build import CORNERS, _nested

    if args.cpu_as_gpu:
        build.device_kind = lambda device: "gpu"
    reinsert, treelets = args.config.split(",")
    options = {} if reinsert == "default" else {"reinsert_iterations": int(reinsert)}
    if treelets != "default":
        options["treelet_leaves"] = int(treelets)
    context, queue = create_context(os.environ.get("CLRT_TEST_DEVICE") or None)
    print("device:", queue.device.name.strip(), "| driver", queue.device.driver_version, flush=True)
    ws = workspace(context)
    now = {"build": "start", "kernel": None, "since": time.time(), "F": 0, "min_count": 2}

    def watchdog():
        while True:
            time.sleep(1.0)
            if time.time() - now["since"] > args.stall:
                print(f"\nSTALL > {args.stall} s in build {now['build']}, kernel {now['kernel']} "
                      f"(launched, not finished{'' if args.trace else '; run with --trace to name it'})",
                      flush=True)
                os._exit(3)
    threading.Thread(target=watchdog, daemon=True).start()

    def read(name, dtype, n):
        out = np.empty(n, dtype)
        cl.enqueue_copy(now["queue"], out, ws.buffers[name], is_blocking=True)
        return out

    def check_tree(where):
        F = now["F"]
        if F < 2:
            return
        nodes = read("nodes", layouts.BUILD_NODE, 2 * F - 1)
        heights = read("heights", np.int32, F - 1)
        left, right = nodes["lo"].view(np.int32)[:, 3], nodes["hi"].view(np.int32)[:, 3]
        parents, counts = nodes["parent"], nodes["count"]
        seen = np.zeros(2 * F - 1, int)
        assert parents[2 * F - 2] == -1, (where, "the root has a parent")
        stack, post = [2 * F - 2], []
        while stack:
            n = stack.pop()
            seen[n] += 1
            assert seen[n] == 1, (where, "node reached twice", n)
            post.append(n)
            if n >= F:
                for c in (int(left[n]), int(right[n])):
                    assert 0 <= c < 2 * F - 1 and parents[c] == n, (where, "child link", n, c)
                    stack.append(c)
        assert (seen == 1).all(), (where, "nodes outside the tree", np.nonzero(seen != 1)[0])
        count, height = np.ones(2 * F - 1, int), np.ones(2 * F - 1, int)
        for n in reversed(post):
            if n >= F:
                count[n] = count[left[n]] + count[right[n]]
                height[n] = 1 + max(height[left[n]], height[right[n]])
                assert counts[n] == count[n], (where, "count", n, counts[n], count[n])
                assert heights[n - F] == height[n], (where, "height", n, heights[n - F], height[n])

    def check_order():
        F = now["F"]
        nodes = read("nodes", layouts.BUILD_NODE, 2 * F - 1)
        heights = read("heights", np.int32, F - 1)
        state = read("state", np.int32, STATE["STATE_INTS"])
        listed = int(state[STATE["STATE_LEVELS"]:STATE["STATE_LEVEL_CURSORS"]].sum())
        order = read("keys0", np.int32, F)[:listed].tolist()
        want = [F + i for i in range(F - 1) if nodes["count"][F + i] >= now["min_count"]]
        assert sorted(order) == want, ("treelet order is not the listed nodes", order, want)
        assert (np.diff(np.minimum(heights[np.array(order, int) - F], 63)) >= 0).all() if order else True
        place = {n: k for k, n in enumerate(order)}
        left, right = nodes["lo"].view(np.int32)[:, 3], nodes["hi"].view(np.int32)[:, 3]
        for n in order:
            for c in (left[n], right[n]):
                if c >= F and nodes["count"][c] >= now["min_count"]:
                    assert place[c] < place[n], ("a child listed after its parent", c, n)
        done = read("keys1", np.uint32, max(F - 1, 1))[:F - 1]
        assert not done.any(), ("treelet_done not clear", done)

    if args.trace or args.check:
        original = cl.enqueue_nd_range_kernel

        def traced(q, kernel, *a, **kw):
            now["kernel"] = kernel.function_name
            event = original(q, kernel, *a, **kw)
            now["queue"] = q
            q.finish()
            if args.check:
                name = kernel.function_name
                if name in ("ploc_top", "reinsert_refit", "treelet_restructure"):
                    check_tree(name)
                elif name == "treelet_order":
                    check_order()
            now["kernel"] = None
            return event
        build.cl.enqueue_nd_range_kernel = traced   # clrt.device.build's pyopencl

    cases = [(name, volume, leaf, {}) for name in sorted(CORNERS) for volume in VOLUMES for leaf in (1, 4)]
    cases += [(name, "box", leaf, {"treelet_leaves": 7, "treelet_min": 0,
                                   **({"top_clusters": 1} if name == "nested" else {})})
              for name in sorted(CORNERS) + ["nested"] for leaf in (1, 4)]
    meshes = {name: (_nested() if name == "nested" else CORNERS[name]()) for name in sorted(CORNERS) + ["nested"]}
    for rep in range(args.reps):
        start = time.time()
        for name, volume, leaf, extra in cases:
            corners = meshes[name]
            kw = {**options, **extra}
            if "treelet_leaves" in options and "treelet_leaves" in extra:
                kw["treelet_leaves"] = options["treelet_leaves"]
            label = f"rep {rep} {name}-{volume}-{leaf} {extra or ''}"
            now.update(build=label, since=time.time(), F=len(corners),
                       min_count=max(leaf + 1, int(kw.get("treelet_min", 0) or 0)))
            print(f"  {label} ...", end="", flush=True)
            try:
                bvh = build_on_device(context, queue, corners, volume=volume, leaf_size=leaf, keep_boxes=True, **kw)
                rows, prim_ids = bvh.read_back()
                assert np.array_equal(np.sort(prim_ids), np.arange(len(corners))), "prim_ids not a permutation"
            except AssertionError as exc:
                print(f" CHECK FAILED: {exc}", flush=True)
                return 2
            print(f" ok {1e3 * (time.time() - now['since']):.1f} ms", flush=True)
        print(f"rep {rep} done ({time.time() - start:.1f} s)", flush=True)
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=20)
    p.add_argument("--timeout", type=float, default=300.0, help="seconds a configuration's process may take")
    p.add_argument("--stall", type=float, default=30.0, help="seconds one build may take before the watchdog ends it")
    p.add_argument("--trace", action="store_true")
    p.add_argument("--check", action="store_true")
    p.add_argument("--cpu-as-gpu", action="store_true")
    p.add_argument("--config")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    args.trace = args.trace or args.check
    return child(args) if args.child else parent(args)


if __name__ == "__main__":
    sys.exit(main())
