"""Shared fixtures: the OpenCL device under test and small generated meshes.

Tests run on the device clrt would choose (PoCL on a machine without a GPU);
set CLRT_TEST_DEVICE (e.g. 'cpu', 'gpu', '0:1') to pick another.
"""

import os
from pathlib import Path

import numpy as np
import pytest

from clrt.scene import primitives
from clrt.scene.mesh import Mesh

# "auto" builds on the device in every test, whatever PoCL's cache holds (a
# machine's first builds run on the host: clrt.device.first_build,
# tests/test_first_build.py turns it on).  Set before any test's subprocess.
os.environ["CLRT_FIRST_BUILD"] = "0"

REPO = Path(__file__).resolve().parents[1]
SHARED_MESHES = REPO.parent / "shared" / "meshes"


def write_icosphere_obj(path: Path) -> Path:
    """A small closed mesh (an icosphere) written as an OBJ file at ``path``."""
    mesh = primitives.icosphere(1)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


# Test-only faults: a sitecustomize module that every Python process started
# with fault_hook()'s folder on its path loads -- the command and the batch's
# worker processes (restarted ones too).  Rendering a source named boom.obj
# raises; die.obj kills the worker process each time; flaky.obj kills it the
# first time only (SOURCE.kills, beside the source, lists the processes killed);
# hang.obj never returns from its task, hangonce.obj the first time only
# (SOURCE.hangs lists the processes that hung).  CLRT_TEST_HANG_FLOOR sets the
# batch's BATCH_HANG_FLOOR, CLRT_TEST_FIRST_TASK_SETUP its BATCH_FIRST_TASK_SETUP.
# With CLRT_TEST_SETUP_CRASH=all in the environment, every worker process dies
# while its device is set up (clrt.batch.worker.configure), before any task;
# with CLRT_TEST_SETUP_CRASH=PATH, every one but the first (which makes PATH).
# CLRT_TEST_NO_WORKER_TIMEOUT sets the batch's BATCH_NO_WORKER_TIMEOUT.  With
# CLRT_TEST_TRACE_KILL=PATH, the first chunk that clrt.batch.trace sends to a
# worker kills it (and makes PATH).
# A killer dies 0.3 s into its task, as a driver that crashes mid-render: the
# tasks sent to its worker after it are surely there, waiting.
FAULTS = '''
import os
import time
import clrt.scene.render_setup as setup
_render_scene = setup.render_scene

def render_scene(source, **options):
    name = os.path.basename(str(source))
    if name == "boom.obj":
        raise RuntimeError("boom from the test")
    if name == "hang.obj" or name == "hangonce.obj" and not os.path.exists(str(source) + ".hangs"):
        with open(str(source) + ".hangs", "a") as hangs:
            hangs.write(f"{os.getpid()}\\n")
        while True:   # a driver call that never returns
            time.sleep(1)
    if name == "die.obj" or name == "flaky.obj" and not os.path.exists(str(source) + ".kills"):
        with open(str(source) + ".kills", "a") as kills:
            kills.write(f"{os.getpid()}\\n")
        time.sleep(0.3)
        os._exit(1)
    return _render_scene(source, **options)

setup.render_scene = render_scene

if os.environ.get("CLRT_TEST_SETUP_CRASH"):
    # worker processes die while they set up their device, as a driver that
    # crashes when a context is made: before they run any task
    import clrt.batch.worker as worker

    def configure(device, cache_size=worker.BATCH_CACHE_SCENES, _configure=worker.configure):
        mark = os.environ["CLRT_TEST_SETUP_CRASH"]
        if mark != "all":   # a file: the first setup makes it and lives, every later one dies
            try:
                os.close(os.open(mark, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
                return _configure(device, cache_size)
            except FileExistsError:
                pass
        os._exit(1)

    worker.configure = configure

if os.environ.get("CLRT_TEST_TRACE_KILL"):
    # the first chunk of rays that clrt.batch.trace sends to a worker kills its
    # process (the file named there remembers): later ones trace
    import clrt.batch.rays as rays

    def trace_chunk(*args, _trace_chunk=rays.trace_chunk, **kwargs):
        try:
            os.close(os.open(os.environ["CLRT_TEST_TRACE_KILL"], os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return _trace_chunk(*args, **kwargs)
        os._exit(1)

    rays.trace_chunk = trace_chunk

if os.environ.get("CLRT_TEST_NO_WORKER_TIMEOUT"):   # the batch's watchdog, in the command's process
    import clrt.batch.watch as watch
    watch.BATCH_NO_WORKER_TIMEOUT = float(os.environ["CLRT_TEST_NO_WORKER_TIMEOUT"])

if os.environ.get("CLRT_TEST_HANG_FLOOR"):   # the batch's hang limit, in the command's process
    import clrt.batch.watch as watch
    watch.BATCH_HANG_FLOOR = float(os.environ["CLRT_TEST_HANG_FLOOR"])

if os.environ.get("CLRT_TEST_FIRST_TASK_SETUP"):   # the hang limit before any frame has finished
    import clrt.batch.watch as watch
    watch.BATCH_FIRST_TASK_SETUP = float(os.environ["CLRT_TEST_FIRST_TASK_SETUP"])
'''


def fault_hook(folder: Path) -> Path:
    """A folder holding the FAULTS module: put it on a subprocess's path (repo_env)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "sitecustomize.py").write_text(FAULTS)
    return folder


def repo_env(*paths) -> dict:
    """The environment with ``paths``, then this checkout, first on PYTHONPATH:
    a subprocess runs the clrt under test."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([*map(str, paths), str(REPO), env.get("PYTHONPATH", "")])
    return env


@pytest.fixture(scope="session")
def device():
    return os.environ.get("CLRT_TEST_DEVICE") or None


def _crossing_quads() -> Mesh:
    """Two quads crossing at right angles plus an exact duplicate of one
    triangle: intersecting, non-manifold, with coincident faces."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [0, -1, -1], [0, -1, 1], [0, 1, 1], [0, 1, -1]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [0, 1, 2]])
    return Mesh.from_arrays(v, f, "crossing quads")


# Meshes made by our own code, so the suite needs no files: closed and open,
# smooth and faceted, with coincident triangles.
TEST_MESHES = {
    "icosphere": lambda: primitives.icosphere(2),
    "box": lambda: primitives.box((1.0, 0.6, 1.4)),
    "torus": lambda: primitives.torus(1.0, 0.35, 24, 12),
    "heightfield": lambda: primitives.heightfield(16),
    "crossing": _crossing_quads,
}


@pytest.fixture(params=sorted(TEST_MESHES))
def test_mesh(request) -> Mesh:
    return TEST_MESHES[request.param]()
