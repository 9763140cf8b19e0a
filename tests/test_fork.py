"""Worker processes (clrt/device/sharing.py): an OpenCL driver does not survive
fork, so a child forked after the driver started gets a one-line DeviceError
(before: it waited forever, with the parent's Accel or a new one); workers
started by "spawn" get an Accel by pickle, and a child forked before any
device work uses OpenCL as any process does.

Pool results are waited for with a generous timeout, so that a regression
fails rather than hangs the suite."""

import multiprocessing
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import clrt
from clrt.scene import primitives

WAIT_S = 120
_CAMERA = clrt.Camera(eye=(0.0, 1.0, 3.0), target=(0.0, 0.0, 0.0), width=24, height=16)
_accel = None      # the parent's, inherited by forked children


def _rays():
    origins = np.array([[0.0, 0.0, 5.0], [0.2, 0.1, 5.0], [3.0, 3.0, 5.0]], np.float32)
    return origins, np.array([0.0, 0.0, -1.0], np.float32)


def _trace_with_parents():
    return _accel.trace(*_rays()).t


def _trace_with_new(device):
    return clrt.Accel(primitives.icosphere(1), device=device).trace(*_rays()).t


def _trace_with_given(accel):
    return accel.trace(*_rays()).t


def _render_with_given(renderer):
    return renderer.render(_CAMERA).image


def _build_on_the_host(device):
    """A new Accel with a host builder: refused before the (long) build."""
    import clrt.query.accel as accel_module

    def build(*args):
        raise AssertionError("the BVH was built first")

    accel_module.build_acceleration = build   # this child only
    return clrt.Accel(primitives.icosphere(1), device=device, builder="sah")


def _outcome(pool, function, *args):
    """What ``function(*args)`` gives in the pool: its value, or its error as text."""
    try:
        return pool.apply_async(function, args).get(timeout=WAIT_S)
    except clrt.ClrtError as exc:
        return f"{type(exc).__name__}: {exc}"


def test_forked_child_refuses_device_work(device):
    """A child forked after this process used the device refuses the parent's
    Accel, a new one (before building its BVH), an Accel and a Renderer given
    by pickle, with one line naming the fix."""
    global _accel
    _accel = clrt.Accel(primitives.icosphere(1), device=device)
    renderer = clrt.Renderer(clrt.scene_from_mesh(primitives.icosphere(1)), device=device)
    try:
        _accel.trace(*_rays())
        with multiprocessing.get_context("fork").Pool(1) as pool:
            outcomes = [_outcome(pool, _trace_with_parents), _outcome(pool, _trace_with_new, device),
                        _outcome(pool, _trace_with_given, _accel), _outcome(pool, _render_with_given, renderer),
                        _outcome(pool, _build_on_the_host, device)]
        for outcome in outcomes:
            assert isinstance(outcome, str) and outcome.startswith("DeviceError: OpenCL was started in process")
            assert "'spawn'" in outcome and "\n" not in outcome
        assert np.isfinite(_accel.trace(*_rays()).t[:2]).all()     # the parent's Accel still answers
    finally:
        _accel = None


def test_spawned_worker_gets_a_pickled_accel_and_renderer(device):
    """With the spawn start method, an Accel and a Renderer sent to a worker
    are built again there and answer as the parent's do."""
    accel = clrt.Accel(primitives.icosphere(1), device=device, builder="sah")
    renderer = clrt.Renderer(clrt.scene_from_mesh(primitives.icosphere(1)), device=device)
    want, image = accel.trace(*_rays()).t, renderer.render(_CAMERA).image
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        got = pool.apply_async(_trace_with_given, (accel,)).get(timeout=WAIT_S)
        rendered = pool.apply_async(_render_with_given, (renderer,)).get(timeout=WAIT_S)
    assert np.array_equal(got, want) and np.isinf(got[2]) and np.isfinite(got[:2]).all()
    assert np.array_equal(rendered, image) and image.any()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_child_forked_before_device_work_uses_the_device(device):
    """A fresh process that forks before touching a device (a server
    pre-forking its workers): the child builds and queries an Accel."""
    script = f"""
import multiprocessing, numpy as np, clrt
from clrt.scene import primitives
def work(_):
    return clrt.Accel(primitives.icosphere(1), device={device!r}).trace(
        np.array([0.0, 0.0, 5.0]), np.array([0.0, 0.0, -1.0])).t.tolist()
with multiprocessing.get_context("fork").Pool(1) as pool:
    print(pool.apply_async(work, (0,)).get(timeout={WAIT_S}))
"""
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env,
                          timeout=2 * WAIT_S)
    assert done.returncode == 0, done.stderr[-2000:]
    t = float(done.stdout.strip().strip("[]"))
    assert 0.9 < 5.0 - t <= 1.0     # the unit icosphere, its facets at most a little inside
