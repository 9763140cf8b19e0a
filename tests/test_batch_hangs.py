"""A worker that hangs inside a task -- a driver call that never returns --
stays connected and up: the batch waited for it for ever.  Now a task running
far past the others (clrt.batch.watch.HangWatch), or past an absolute bound
while no frame has finished (the task timeout, or one from its views and image
size), is cancelled, its worker restarted and the task submitted again;
hanging again, its frames are "device" with one line naming it (exit 3), and
every other frame is done.

As in test_batch_killers: the command runs in a process of its own with the
test's faults (conftest.FAULTS: hang.obj never returns, hangonce.obj the
first time only) and a hang floor of 2 s; two workers, so that the healthy
sources finish and give the median; tiny meshes and images."""

import json
import os
import signal
import subprocess
import sys

import pytest

pytest.importorskip("distributed")

from clrt.config import (BATCH_FIRST_TASK_RAY_SECONDS, BATCH_FIRST_TASK_SETUP, BATCH_HANG_FACTOR,  # noqa: E402
                         BATCH_HANG_FLOOR, BATCH_MANIFEST, DEFAULT_HEIGHT, DEFAULT_SAMPLES, DEFAULT_WIDTH)
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


# --------------------------------------------------------------------------- before any frame has finished
# A task that hangs with no frame of the batch finished had nothing to be compared
# with, and the batch waited for ever.  Now it is bounded: by the task timeout
# given, else by BATCH_FIRST_TASK_SETUP plus BATCH_FIRST_TASK_RAY_SECONDS per
# camera ray (shrunk here through the fault hook).  The commands run in a session
# of their own: a batch that still waits (the code before the bound) is killed
# with its worker processes and fails the test, instead of hanging the suite.

def _run(args, env, timeout=150):
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"the batch still waited after {timeout} s: a hang before any frame finished is not bounded")
    return proc.returncode, out, err


@pytest.mark.parametrize("bound", ["--task-timeout", "default"])
def test_a_lone_hung_task_is_bounded_retried_and_reported(bound, tmp_path, device):
    env = repo_env(fault_hook(tmp_path / "hook"))
    src = tmp_path / "src"
    src.mkdir()
    hanger = write_icosphere_obj(src / "hang.obj")
    out = tmp_path / "out"
    if bound == "default":   # the first-task bound, its set-up allowance shrunk to 3 s
        env["CLRT_TEST_FIRST_TASK_SETUP"] = "3"
        limit = ["--workers", "1"]
        rule = (f"no frame had finished: 3 s for set-up and {BATCH_FIRST_TASK_RAY_SECONDS * 1e6:g} us per camera "
                "ray; --task-timeout (task_timeout=) sets another")
    else:
        limit = ["--task-timeout", "3"]
        rule = "the task timeout given"
    dev = ["--device", device] if device else []
    rc, _, err = _run([sys.executable, "-m", "clrt", "batch", "render", str(hanger), "-o", str(out), "--views", "2",
                       "--width", "20", "--height", "14", "-q", *limit, *dev], env)
    assert rc == 3, err[-2000:]
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err[-2000:]
    assert lines[0] == (f"clrt: {hanger}: hung: the task of views 0-1 ran past 3.0 s 2 times ({rule}); its worker "
                        "was restarted each time"), lines
    hangs = (src / "hang.obj.hangs").read_text().splitlines()
    assert len(hangs) == 2 and hangs[0] != hangs[1], "hung twice, in two worker processes"
    records = [json.loads(line) for line in (out / BATCH_MANIFEST).read_text().splitlines()]
    assert [(r["view"], r["status"]) for r in records] == [(0, "device"), (1, "device")]
    assert not (out / "hang").exists() or not any((out / "hang").iterdir()), "no frame, not even a partial one"
    assert not (out / ".clrt-runs").exists()


RENDER_ONCE = '''
import sys
import clrt.batch

if __name__ == "__main__":
    device = sys.argv[3] if len(sys.argv) > 3 else None
    summary = clrt.batch.run([sys.argv[1]], sys.argv[2], views=2, width=20, height=14, workers=1, device=device,
                             task_timeout=10)
    print(" ".join(o.status for o in summary.outputs))
'''


def test_a_lone_task_that_hangs_once_ends_done_on_its_retry(tmp_path, device):
    # task_timeout=10, not 3: the retry, on a restarted worker, must render
    # within it (program builds included, on a cold cache)
    env = repo_env(fault_hook(tmp_path / "hook"))
    src = tmp_path / "src"
    src.mkdir()
    hanger = write_icosphere_obj(src / "hangonce.obj")
    script = tmp_path / "render_once.py"
    script.write_text(RENDER_ONCE)
    out = tmp_path / "out"
    rc, printed, err = _run([sys.executable, str(script), str(hanger), str(out), *([device] if device else [])], env)
    assert rc == 0 and printed.split() == ["done", "done"], err[-2000:]
    assert len((src / "hangonce.obj.hangs").read_text().splitlines()) == 1
    assert sorted(p.name for p in (out / "hangonce").glob("view-*")) == ["view-0000.png", "view-0001.png"]


@pytest.mark.parametrize("value, shown", [("0", "0"), ("-1", "-1"), ("abc", "'abc'"), ("inf", "inf")])
def test_a_bad_task_timeout_is_one_line(value, shown, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", str(tmp_path / "none.obj"),
                           "-o", str(tmp_path / "out"), "--task-timeout", value],
                          env=repo_env(), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"clrt: --task-timeout must be a number > 0, got {shown}"]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", [0, -2.5, float("nan"), "60", True])
def test_the_api_checks_task_timeout_before_anything_starts(value, tmp_path):
    import clrt
    import clrt.batch
    with pytest.raises(clrt.InputError, match=r"^task_timeout must be a number > 0, got "):
        clrt.batch.render([str(tmp_path / "none.obj")], tmp_path / "out", task_timeout=value)
    assert not (tmp_path / "out").exists()


def test_the_hang_limit_rules():
    """Before any frame: the set-up allowance plus the camera rays of the task's
    views, or the timeout given; after: the median's limit, capped by the timeout."""
    from clrt.batch.watch import HangWatch
    first = BATCH_FIRST_TASK_SETUP + BATCH_FIRST_TASK_RAY_SECONDS * 8 * 640 * 480
    assert HangWatch(None, dict).limit(8, 640 * 480)[0] == pytest.approx(first)
    assert HangWatch(None, dict, timeout=3.0).limit(8, 640 * 480) == (3.0, "the task timeout given")
    frames = [{"status": "done", "seconds": s} for s in (1.0, 2.0, 30.0)]
    for timeout, expected in [(None, max(BATCH_HANG_FACTOR * 2.0 * 8, BATCH_HANG_FLOOR)), (60.0, 60.0),
                              (1e6, max(BATCH_HANG_FACTOR * 2.0 * 8, BATCH_HANG_FLOOR))]:
        watch = HangWatch(None, dict, timeout=timeout)
        watch.finished(frames)
        assert watch.limit(8, 640 * 480)[0] == expected, timeout


def test_camera_rays_come_from_the_options_else_the_scene_file_else_the_defaults(tmp_path):
    from clrt.batch.jobs import camera_rays
    scene = tmp_path / "s.toml"
    scene.write_text("[camera]\nwidth = 800\nheight = 600\n[render]\nsamples = 2\n")
    assert camera_rays(str(scene), {}, {}) == 800 * 600 * 4
    assert camera_rays(str(scene), {"samples": 3}, {"width": 10}) == 10 * 600 * 9
    assert camera_rays(str(tmp_path / "m.obj"), {}, {}) == DEFAULT_WIDTH * DEFAULT_HEIGHT * DEFAULT_SAMPLES ** 2
    (tmp_path / "bad.toml").write_text("[camera\n")
    assert camera_rays(str(tmp_path / "bad.toml"), {}, {}) == DEFAULT_WIDTH * DEFAULT_HEIGHT * DEFAULT_SAMPLES ** 2
