"""Worker processes that die while they start -- a driver crashing when the
device is set up (clrt.batch.worker.DevicePlugin), before any task runs -- are
restarted by their nanny for ever, and no task is ever charged with their
deaths.  The batch's watchdog (clrt.batch.watch.Watchdog) stops such a batch
once no worker has been up for BATCH_NO_WORKER_TIMEOUT seconds: its frames are
"device", one line says why, exit 3, the cluster shut down.  A healthy batch
never hears of it, even with a tiny timeout.

As in test_batch_killers: the command runs in a process of its own, with the
test's faults (conftest.FAULTS) and a short timeout; tiny meshes and images."""

import json
import subprocess
import sys
import time

import pytest

pytest.importorskip("distributed")

from clrt.config import BATCH_MANIFEST  # noqa: E402
from conftest import fault_hook, repo_env, write_icosphere_obj  # noqa: E402

TIMEOUT = 3
STOPPED = (f"clrt: no worker stayed up for {TIMEOUT} s: every worker process died while starting its device "
           "({starts}; a crash in the OpenCL driver?); finished images are kept: run the same command again "
           "once the device works")


def _batch(tmp_path, names, device, crash=None, timeout=TIMEOUT):
    env = repo_env(fault_hook(tmp_path / "hook"))
    env["CLRT_TEST_NO_WORKER_TIMEOUT"] = str(timeout)
    if crash:
        env["CLRT_TEST_SETUP_CRASH"] = crash
    sources = [write_icosphere_obj(tmp_path / "src" / name) for name in names]
    out = tmp_path / "out"
    dev = ["--device", device] if device else []
    began = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", *map(str, sources), "-o", str(out),
                           "--views", "2", "--width", "20", "--height", "14", "--workers", "1", "-q", *dev],
                          env=env, capture_output=True, text=True, timeout=120)
    records = [json.loads(line) for line in (out / BATCH_MANIFEST).read_text().splitlines()]
    return proc, time.monotonic() - began, {(r["source"].rsplit("/", 1)[-1], r["view"]): r for r in records}, out


@pytest.fixture
def src(tmp_path):
    (tmp_path / "src").mkdir()


@pytest.mark.parametrize("crash", ["all", "restarts"])
def test_a_batch_whose_workers_die_starting_stops(crash, tmp_path, src, device):
    """"all": every worker dies setting up its device, the first one too (the
    plugin's registration fails); "restarts": the first one lives, die.obj kills
    it, and each restarted one dies starting -- the batch waited for ever."""
    names = ("ball.obj",) if crash == "all" else ("die.obj", "ball.obj")
    mark = "all" if crash == "all" else str(tmp_path / "first-setup")
    proc, seconds, records, out = _batch(tmp_path, names, device, crash=mark)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 3, proc.stderr[-2000:]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    starts = lines[0].split("(", 1)[1].split(";", 1)[0]
    assert starts.endswith("start(s)") and int(starts.split()[0]) >= 1, lines
    assert lines[0] == STOPPED.format(starts=starts)
    assert seconds < 60, seconds
    assert set(records) == {(name, v) for name in names for v in (0, 1)}
    assert {r["status"] for r in records.values()} == {"device"}
    assert all(r["error"] == lines[0].removeprefix("clrt: ") for r in records.values())
    assert not list(out.rglob("*.png"))
    assert {p.name for p in out.iterdir() if p.name.startswith(".")} <= {".clrt-batch.lock", ".manifest.jsonl.clrt"}


def test_a_healthy_batch_never_hears_of_the_watchdog(tmp_path, src, device):
    """A timeout of 1 s: the batch's worker is up (its device set up) and the
    batch runs on, whatever its tasks take."""
    proc, _, records, out = _batch(tmp_path, ("ball.obj", "block.obj"), device, timeout=1)
    assert proc.returncode == 0 and not proc.stderr.strip(), proc.stderr[-2000:]
    assert {r["status"] for r in records.values()} == {"done"} and len(records) == 4


def test_a_scheduler_without_workers_is_given_up_after_the_timeout(tmp_path, monkeypatch, capsys):
    """--scheduler with no worker at all waited until Ctrl-C: it stops after
    BATCH_NO_WORKER_TIMEOUT (here 2 s), exit 3, one line, its frames "device"."""
    import logging

    from distributed import LocalCluster

    from clrt.cli import main
    monkeypatch.setattr("clrt.batch.watch.BATCH_NO_WORKER_TIMEOUT", 2.0)
    mesh = write_icosphere_obj(tmp_path / "ball.obj")
    out = tmp_path / "out"
    with LocalCluster(n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1", scheduler_port=0,
                      dashboard_address=None, silence_logs=logging.CRITICAL) as cluster:
        code = main(["batch", "render", str(mesh), "-o", str(out), "--views", "2", "--width", "20", "--height",
                     "14", "--scheduler", cluster.scheduler_address, "-q"])
    err = capsys.readouterr().err
    assert code == 3, err
    assert err == ("clrt: no worker stayed up for 2 s: the scheduler has no workers (docs/distributed.md: starting "
                   "them); finished images are kept: run the same command again once it has workers\n"), err
    records = json.loads("[" + ",".join((out / BATCH_MANIFEST).read_text().splitlines()) + "]")
    assert [(r["view"], r["status"]) for r in records] == [(0, "device"), (1, "device")]
