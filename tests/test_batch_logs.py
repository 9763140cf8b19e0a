"""What clrt batch render prints when frames fail or the cluster goes away:
clrt's own lines, never Dask's log lines or tracebacks (found by an audit of
-q).  The command runs as a user runs it, in a process of its own; tasks are
made to fail in the worker processes by a sitecustomize module on their path.
Small: tiny images, one local worker."""

import subprocess
import sys
import time

import pytest

pytest.importorskip("distributed")

from clrt.batch.cluster import start_local_cluster  # noqa: E402
from conftest import fault_hook, repo_env, write_icosphere_obj  # noqa: E402


def _dask_lines(err):
    return [line for line in err.splitlines() if "distributed." in line or "Traceback" in line
            or " - ERROR - " in line or " - WARNING - " in line]


@pytest.mark.parametrize("quiet", [True, False], ids=["quiet", "verbose"])
def test_failed_frames_are_clrt_lines_not_dask_logs(quiet, tmp_path, device):
    hook = fault_hook(tmp_path / "hook")
    sources = [write_icosphere_obj(tmp_path / name) for name in ("ball.obj", "boom.obj", "die.obj")]
    (tmp_path / "corrupt.obj").write_text("v 1 2\nf 1 2 3\n")
    dev = ["--device", device] if device else []
    proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", *map(str, sources),
                           str(tmp_path / "corrupt.obj"), "-o", str(tmp_path / "out"), "--width", "20",
                           "--height", "14", "--workers", "1", *(["-q"] if quiet else []), *dev],
                          env=repo_env(hook), capture_output=True, text=True, timeout=180)
    err = proc.stderr
    assert proc.returncode == 3, err[-2000:]   # device: the worker that kept dying
    assert not _dask_lines(err), err[-2000:]
    # boom.obj fails with its own error, also when it waited on the worker that
    # die.obj killed (tests/test_batch_killers.py)
    assert "boom.obj: RuntimeError: boom from the test" in err and "die.obj: KilledWorker" in err
    assert "corrupt.obj" in err and "ball.obj" not in err
    if quiet:
        assert all(line.startswith("clrt: ") for line in err.splitlines()), err[-2000:]


def test_losing_the_scheduler_prints_one_line(tmp_path, device):
    # the command's own Client logs the lost connection (with tracebacks) unless told not to
    mesh = write_icosphere_obj(tmp_path / "ball.obj")
    out = tmp_path / "out"
    dev = ["--device", device] if device else []
    cluster = start_local_cluster(1, device)
    proc = None
    try:
        proc = subprocess.Popen([sys.executable, "-m", "clrt", "batch", "render", str(mesh), "-o", str(out),
                                 "--views", "5000", "--width", "32", "--height", "24", "--samples", "4",
                                 "--scheduler", cluster.scheduler_address, "-q", *dev],
                                env=repo_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while not list(out.glob("ball/view-*.png")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before its scheduler went away"
        cluster.close()
        _, err = proc.communicate(timeout=90)
    finally:
        cluster.close()
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 3, err[-2000:]
    assert err.startswith("clrt: lost the Dask cluster") and len(err.strip().splitlines()) == 1, err[-2000:]
