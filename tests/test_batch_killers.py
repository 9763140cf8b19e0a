"""A task that kills its worker process (a crash in the OpenCL driver, say)
takes no healthy task down with it: with one worker or two, the killer is
reported ("device", exit 3) and every other frame is rendered; a task that
kills its worker only the first time it runs ends done.  Dask's scheduler
counts a worker's death against every task it had sent to that worker, running
or waiting (clrt.batch.engine._execute says what clrt does about it).

The command runs as a user runs it, in a process of its own, with the test's
faults (conftest.FAULTS) loaded by its worker processes.  Small: tiny meshes,
two views each, tiny images."""

import json
import subprocess
import sys

import pytest

pytest.importorskip("distributed")

from clrt.config import BATCH_MANIFEST  # noqa: E402
from conftest import fault_hook, repo_env, write_icosphere_obj  # noqa: E402

HEALTHY = ("ball.obj", "block.obj", "cone.obj")
KILLERS = {"die": ("die.obj",), "flaky": ("flaky.obj",), "two": ("a/die.obj", "b/die.obj")}
KILLED = ("clrt: {source}: KilledWorker: the worker process running it died each time it was tried "
          "(a crash, or out of memory?)")

# (killer, workers, Dask's allowed-failures).  Dask's own setting (3), and 0,
# where a death fails every task that was sent to the worker at once: the
# tasks queued behind the killer on its first attempt, a case that does not
# depend on the order in which a restarted worker gets its tasks back.  "two":
# two killers on one worker, each waiting behind the other in turn (their
# deaths go on for more than the 15 s after which Dask's LocalCluster gave up
# on a worker that was restarting just then: the batch waited for ever).
CASES = [("die", 1, None), ("die", 2, None), ("die", 1, 0), ("die", 2, 0), ("flaky", 1, None), ("flaky", 2, None),
         ("two", 1, None)]


@pytest.mark.parametrize("killer, workers, allowed", CASES)
def test_a_task_that_kills_its_worker_takes_no_healthy_task_with_it(killer, workers, allowed, tmp_path, device):
    hook = fault_hook(tmp_path / "hook")
    env = repo_env(hook)
    if allowed is not None:
        env["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"] = str(allowed)
    src = tmp_path / "src"
    for name in KILLERS[killer]:
        (src / name).parent.mkdir(parents=True, exist_ok=True)
    # the killers first: they are sent first, and the healthy tasks wait behind them on their worker
    sources = [write_icosphere_obj(src / name) for name in (*KILLERS[killer], *HEALTHY)]
    out = tmp_path / "out"
    dev = ["--device", device] if device else []
    proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", *map(str, sources), "-o", str(out),
                           "--views", "2", "--width", "20", "--height", "14", "--workers", str(workers), "-q",
                           *dev], env=env, capture_output=True, text=True, timeout=240)
    err = proc.stderr
    records = [json.loads(line) for line in (out / BATCH_MANIFEST).read_text().splitlines()]
    status = {(str(src.joinpath(r["source"]).relative_to(src)), r["view"]): r["status"] for r in records}
    healthy = {(name, v): "done" for name in HEALTHY for v in (0, 1)}
    kills = {name: len((src / f"{name}.kills").read_text().splitlines()) for name in KILLERS[killer]}
    if killer == "flaky":
        assert proc.returncode == 0 and not err.strip(), err[-2000:]
        assert kills == {"flaky.obj": 1}
        assert status == {**healthy, ("flaky.obj", 0): "done", ("flaky.obj", 1): "done"}
    else:
        assert proc.returncode == 3, err[-2000:]
        assert sorted(err.strip().splitlines()) == sorted(KILLED.format(source=src / name)
                                                          for name in KILLERS[killer]), err[-2000:]
        assert status == {**healthy, **{(name, v): "device" for name in KILLERS[killer] for v in (0, 1)}}
        # Dask's allowed-failures + 1 deaths each; for a killer that also waited
        # behind another, the deaths of its last submission may go beyond that
        allowed = 3 if allowed is None else allowed
        most = allowed + 1 if len(kills) == 1 else 2 * allowed + 1
        assert all(allowed + 1 <= n <= most for n in kills.values()), kills
    done = sorted(r["path"] for r in records if r["status"] == "done")
    assert done == sorted(p.relative_to(out).as_posix() for p in out.rglob("*.png"))
    assert {p.name for p in out.iterdir() if p.name.startswith(".")} <= {".clrt-batch.lock", ".manifest.jsonl.clrt"}


def test_ray_queries_survive_a_killed_worker(tmp_path, device):
    """clrt.batch.trace on a cluster of one worker, whose process the first chunk
    of rays kills: Dask retries the chunk on the restarted worker, and the hits
    are those of clrt.trace.  The mesh used to be scattered to the workers, and
    died with them ("lost dependencies")."""
    marker = tmp_path / "killed"
    env = repo_env(fault_hook(tmp_path / "hook"))
    env["CLRT_TEST_TRACE_KILL"] = str(marker)
    code = f"""
import numpy as np, dask, dask.array as da
from distributed import Client
import clrt, clrt.batch
from clrt.batch.cluster import start_local_cluster
from clrt.scene import primitives
if __name__ == "__main__":
    mesh = primitives.torus(1.0, 0.35, 16, 8)
    rng = np.random.default_rng(5)
    origins = rng.normal(size=(2000, 3)) * 3.0
    directions = -origins + rng.normal(size=(2000, 3))
    with start_local_cluster(1, {device!r}) as cluster, Client(cluster) as client:
        o, d = (da.from_array(a, chunks=(500, 3)) for a in (origins, directions))
        hits = clrt.batch.trace(mesh, o, d, client=client, device={device!r})
        t, prim = dask.compute(hits.t, hits.prim)
        blocked = clrt.batch.occluded(mesh, o, d, tmax=2.0, client=client, device={device!r}).compute()
    want = clrt.trace(mesh, origins, directions, device={device!r})
    assert 0 < (want.prim >= 0).sum() < len(origins)
    assert np.array_equal(prim, want.prim) and np.array_equal(t, want.t)
    assert np.array_equal(blocked, clrt.occluded(mesh, origins, directions, tmax=2.0, device={device!r}))
    print("same hits")
"""
    script = tmp_path / "trace.py"
    script.write_text(code)
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=180)
    assert marker.exists(), "a worker was killed"
    assert proc.returncode == 0 and proc.stdout.strip() == "same hits", proc.stderr[-2000:]
