"""A task that kills its worker process (a crash in the OpenCL driver, say)
takes no healthy task down with it: with one worker or two, the killer is
reported ("device", exit 3) and every other frame is rendered; a task that
kills its worker only the first time it runs ends done.  Dask's scheduler
counts a worker's death against every task it had sent to that worker, running
or waiting (clrt.batch.engine explains what clrt does about it).

The command runs as a user runs it, in a process of its own, with the test's
faults (conftest.FAULTS) loaded by its worker processes.  Small: four tiny
meshes, two views each, tiny images."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from clrt.config import BATCH_KILLED_RESUBMITS, BATCH_MANIFEST  # noqa: E402
from conftest import fault_hook, repo_env, write_icosphere_obj  # noqa: E402

HEALTHY = ("ball", "block", "cone")
KILLED = ("clrt: {source}: KilledWorker: the worker process running it died each time it was tried "
          "(a crash, or out of memory?)")


# (killer, workers, Dask's allowed-failures): Dask's own setting (3), and 0, where
# a death fails every task that was sent to the worker at once: the tasks
# queued behind the killer on its first attempt, a case that does not depend
# on the order in which a restarted worker gets its tasks back.
CASES = [("die", 1, None), ("die", 2, None), ("die", 1, 0), ("die", 2, 0), ("flaky", 1, None), ("flaky", 2, None)]


@pytest.mark.parametrize("killer, workers, allowed", CASES)
def test_a_task_that_kills_its_worker_takes_no_healthy_task_with_it(killer, workers, allowed, tmp_path, device):
    hook = fault_hook(tmp_path / "hook")
    env = repo_env(hook)
    if allowed is not None:
        env["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"] = str(allowed)
    (tmp_path / "src").mkdir()
    # the killer first: it is sent first, and the healthy tasks wait behind it on its worker
    sources = [write_icosphere_obj(tmp_path / "src" / f"{name}.obj") for name in (killer, *HEALTHY)]
    out = tmp_path / "out"
    dev = ["--device", device] if device else []
    proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", *map(str, sources), "-o", str(out),
                           "--views", "2", "--width", "20", "--height", "14", "--workers", str(workers), "-q",
                           *dev], env=env, capture_output=True, text=True, timeout=240)
    err = proc.stderr
    records = [json.loads(line) for line in (out / BATCH_MANIFEST).read_text().splitlines()]
    status = {(Path(r["source"]).stem, r["view"]): r["status"] for r in records}
    healthy = {(name, v): "done" for name in HEALTHY for v in (0, 1)}
    if killer == "die":
        assert proc.returncode == 3, err[-2000:]
        assert err.strip().splitlines() == [KILLED.format(source=sources[0])], err[-2000:]
        assert status == {**healthy, ("die", 0): "device", ("die", 1): "device"}
        assert not (out / "die").exists() or not list((out / "die").iterdir())
        # Dask's allowed-failures + 1 deaths, and more only for a submission of
        # the killer that waited behind another task through a death
        kills = len((tmp_path / "src" / "die.obj.kills").read_text().splitlines())
        deaths = (3 if allowed is None else allowed) + 1
        assert deaths <= kills <= deaths * (BATCH_KILLED_RESUBMITS + 1)
        if allowed == 0:   # it runs first, so its first death is charged to it alone
            assert kills == 1
    else:
        assert proc.returncode == 0 and not err.strip(), err[-2000:]
        assert len((tmp_path / "src" / "flaky.obj.kills").read_text().splitlines()) == 1
        assert status == {**healthy, ("flaky", 0): "done", ("flaky", 1): "done"}
    done = sorted(r["path"] for r in records if r["status"] == "done")
    assert done == sorted(p.relative_to(out).as_posix() for p in out.rglob("*.png"))
    assert {p.name for p in out.iterdir() if p.name.startswith(".")} <= {".clrt-batch.lock", ".manifest.jsonl.clrt"}
