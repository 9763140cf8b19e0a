"""A worker that hangs inside a task -- a driver call that never returns --
stays connected and up: the batch waited for it for ever.  Now a task running
far past the others (clrt.batch.watch.HangWatch) is cancelled, its worker
restarted and the task submitted again; hanging again, its frames are
"device" with one line naming it (exit 3), and every other frame is done.

As in test_batch_killers: the command runs in a process of its own with the
test's faults (conftest.FAULTS: hang.obj never returns, hangonce.obj the
first time only) and a hang floor of 2 s; two workers, so that the healthy
sources finish and give the median; tiny meshes and images."""

import json
import subprocess
import sys

import pytest

pytest.importorskip("distributed")

from clrt.config import BATCH_HANG_FACTOR, BATCH_MANIFEST  # noqa: E402
from conftest import fault_hook, repo_env, write_icosphere_obj  # noqa: E402

FLOOR = 2
HEALTHY = ("ball.obj", "block.obj")


@pytest.mark.parametrize("hanger", ["hang.obj", "hangonce.obj"])
def test_a_hung_task_is_retried_on_a_restarted_worker_then_reported(hanger, tmp_path, device):
    env = repo_env(fault_hook(tmp_path / "hook"))
    env["CLRT_TEST_HANG_FLOOR"] = str(FLOOR)
    src = tmp_path / "src"
    src.mkdir()
    # the hanging source first: it is sent first and runs while the others finish
    sources = [write_icosphere_obj(src / name) for name in (hanger, *HEALTHY)]
    out = tmp_path / "out"
    dev = ["--device", device] if device else []
    proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", *map(str, sources), "-o", str(out),
                           "--views", "2", "--width", "20", "--height", "14", "--workers", "2", "-q", *dev],
                          env=env, capture_output=True, text=True, timeout=240)
    err = proc.stderr
    records = [json.loads(line) for line in (out / BATCH_MANIFEST).read_text().splitlines()]
    status = {(r["source"].rsplit("/", 1)[-1], r["view"]): r["status"] for r in records}
    hangs = (src / f"{hanger}.hangs").read_text().splitlines()
    healthy = {(name, v): "done" for name in HEALTHY for v in (0, 1)}
    if hanger == "hangonce.obj":
        assert proc.returncode == 0 and not err.strip(), err[-2000:]
        assert len(hangs) == 1, hangs
        assert status == {**healthy, (hanger, 0): "done", (hanger, 1): "done"}
    else:
        assert proc.returncode == 3, err[-2000:]
        assert len(hangs) == 2 and hangs[0] != hangs[1], "hung twice, in two worker processes"
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, err[-2000:]
        assert lines[0].startswith(f"clrt: {src / hanger}: hung: the task of views 0-1 ran past "), lines
        assert lines[0].endswith(f" s 2 times ({BATCH_HANG_FACTOR:g} x the median frame time per view, at least "
                                 f"{FLOOR} s); its worker was restarted each time"), lines
        assert status == {**healthy, (hanger, 0): "device", (hanger, 1): "device"}
    assert not (out / ".clrt-runs").exists()
