"""What runs inside a Dask worker process: its OpenCL device, the scenes and
meshes it keeps uploaded, and the tasks.

OpenCL contexts belong to one process, so nothing here is ever shipped between
processes: tasks receive paths, options and meshes, and each worker builds its
own device state, once per scene (``BATCH_CACHE_SCENES`` kept, least recently
used dropped).

**One device per worker.**  :class:`DevicePlugin` (registered by clrt.batch on
every worker, also on workers that join or restart later) picks the device:

1. a ``P:D`` device given to the batch (``--device 0:1``): that device;
2. else the worker's ``CLRT_DEVICE`` environment variable (``gpu``, ``cpu``,
   ``P:D``), for clusters started by hand, one worker per GPU;
3. else worker number i (its name in a LocalCluster) takes the i-th GPU -- or the
   i-th CPU device, with no GPU or with ``--device cpu`` -- cyclically.

Device work of one process is serialised by a lock, and on a GPU also by a lock
file shared by every process of the host (``$TMPDIR/clrt-device-P-D.lock``), so
a device is never driven by two jobs at once, even when a cluster has more
workers than GPUs.  CPU devices (PoCL) are shared; a local cluster divides the
cores among its workers instead (clrt.batch.cluster).
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import signal
import tempfile
import threading
import time
from collections import OrderedDict, deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from clrt.config import BATCH_CACHE_SCENES, BATCH_IMAGE_WRITERS, DEVICE_ENV
from clrt.errors import ClrtError, DeviceError, InputError, OutputError
from clrt.query.results import CLOSEST_FIELDS

try:   # plugins need Dask's base class; the rest of this module runs without Dask
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:   # pragma: no cover - clrt.batch checks for Dask before using this
    WorkerPlugin = object

_SPEC_RE = re.compile(r"\d+(:\d+)?")

#: A task stops rendering after this many failed image writes and none written.
OUTPUT_GIVE_UP = 2


class _State:
    """This process's device choice and caches."""

    def __init__(self):
        self.device: str | None = None          # spec given to create_context
        self.lock_file: str | None = None       # host-wide lock of a GPU
        self.cache_size = BATCH_CACHE_SCENES
        self.scenes: OrderedDict = OrderedDict()
        self.accels: OrderedDict = OrderedDict()
        self.unwritable: set = set()            # folders where a task gave up writing
        self.lock = threading.RLock()


_STATE = _State()


def choose_device(requested: str | None, index: int | None) -> str | None:
    """The device spec of worker number ``index`` (see the module's docstring)."""
    if requested and _SPEC_RE.fullmatch(requested.strip()):
        return requested.strip()
    env = os.environ.get(DEVICE_ENV, "").strip()
    if env:
        return env
    from clrt.device.context import list_devices
    devices = list_devices()
    kind = (requested or "").strip().upper() or None
    if kind is None:
        kind = "GPU" if any(d.type == "GPU" for d in devices) else "CPU"
    matching = [d for d in devices if d.type == kind]
    if not matching:
        return requested   # create_context says what exists
    return matching[(index or 0) % len(matching)].index


def worker_index(name) -> int | None:
    """A worker's number: its name in a LocalCluster (0, 1, ...), or the number
    a name such as 'gpu-3' ends with; None for other names."""
    if isinstance(name, int):
        return name
    match = re.search(r"(\d+)$", str(name or ""))
    return int(match.group(1)) if match else None


def configure(device: str | None, cache_size: int = BATCH_CACHE_SCENES) -> None:
    """Use ``device`` for this process's jobs (dropping what another device holds)."""
    with _STATE.lock:
        if device != _STATE.device:
            _STATE.scenes.clear()
            _STATE.accels.clear()
        _STATE.device, _STATE.cache_size = device, max(int(cache_size), 1)
        _STATE.lock_file = None
        try:
            import pyopencl as cl

            from clrt.device.context import list_devices, select_device
            chosen = select_device(device)
            if chosen.type & cl.device_type.GPU:
                for info in list_devices():
                    if info.type == "GPU" and select_device(info.index) == chosen:
                        _STATE.lock_file = os.path.join(
                            tempfile.gettempdir(), f"clrt-device-{info.platform_index}-{info.device_index}.lock")
        except Exception:   # noqa: BLE001 -- no usable device: the jobs report it
            pass


class DevicePlugin(WorkerPlugin):
    """Gives each Dask worker its OpenCL device when it starts (see the module's docstring)."""

    name = "clrt-device"

    def __init__(self, device: str | None = None, cache_size: int = BATCH_CACHE_SCENES,
                 ignore_interrupts: bool = False, token: str | None = None):
        self.device, self.cache_size = device, cache_size
        self.ignore_interrupts = ignore_interrupts   # a local cluster: Ctrl-C is the client's
        self.token = token   # the batch's: its watchdog hears which workers came up

    def setup(self, worker):
        if self.ignore_interrupts and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        configure(choose_device(self.device, worker_index(worker.name)), self.cache_size)
        if self.token is not None:
            # the scheduler adds the worker's address (clrt.batch.watch.Watchdog)
            worker.log_event(READY_TOPIC, {"token": self.token})


#: The scheduler's event topic where a worker says that its device is set up.
READY_TOPIC = "clrt-worker-ready"


@contextmanager
def device_lock():
    """Hold this worker's device: one job at a time per process, and per GPU per host."""
    with _STATE.lock:
        if _STATE.lock_file is None:
            yield
            return
        fd = os.open(_STATE.lock_file, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            os.close(fd)


def _cached(cache: OrderedDict, key, make):
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = make()
    cache[key] = value
    while len(cache) > _STATE.cache_size:
        cache.popitem(last=False)
    return value


def _worker_address() -> str:
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return f"pid {os.getpid()}"


# --------------------------------------------------------------------------- render tasks

def _scene_entry(source: str, scene_options: dict, accel: str, builder: str, leaf_size: int):
    """(Renderer, the scene's own lights) of a source, built once per process."""
    st = os.stat(source)
    # the options came through JSON (engine._plain): colours and the like are lists, so
    # the key holds their JSON text, which is hashable and equal for equal options
    key = (source, st.st_size, st.st_mtime_ns, json.dumps(scene_options, sort_keys=True), accel, builder,
           leaf_size, _STATE.device)

    def make():
        from clrt.renderer import Renderer
        from clrt.scene.render_setup import render_scene
        scene = render_scene(source, **scene_options)
        own = list(scene.lights)   # each view's lights are set before it is rendered
        return Renderer(scene, device=_STATE.device, accel=accel, builder=builder, leaf_size=leaf_size), own

    return _cached(_STATE.scenes, key, make)


def render_task(job: dict) -> list[dict]:
    """:func:`render_views`, its run noted in the task's run log (``job["run_log"]``,
    a file under the output folder named by the batch): a line ``s ADDRESS``
    (this worker's) when it starts and a line ``e`` when it ends, returning or
    raising.  A run that its worker process's death cut short leaves an ``s``
    alone, which tells the batch that this task was running -- not waiting
    behind another task -- when that worker died; a run that goes on far past
    the others, with the worker to restart (clrt.batch.watch)."""
    _note_run(job, f"s {_worker_address()}")
    try:
        return render_views(job)
    finally:
        _note_run(job, "e")


def _note_run(job: dict, mark: str) -> None:
    """Append the line ``mark`` to the task's run log; a log that cannot be written is no
    reason to fail the task (the batch then takes the task as not running)."""
    name = job.get("run_log")
    if not name:
        return
    try:
        with open(Path(job["folder"]) / name, "a", encoding="utf-8") as log:
            log.write(mark + "\n")
    except OSError:
        pass


def render_views(job: dict) -> list[dict]:
    """Render views of one source into the output folder; one record per view.

    ``job``: source, name, views, replace, count (views of the turntable), folder,
    paths (their suffix names the format), scene and camera options, lights,
    accel, builder, leaf_size, bit_depth (None, or 16 for 16-bit PNG), force, key.
    Views whose image is there, exactly as clrt wrote it, are skipped unless
    listed in ``replace`` (a retry after a lost worker redoes only what is
    missing); a view in ``replace`` is written over whatever is there (the
    batch judged that file before it started).  Errors of the source or
    the device become records, never exceptions: "bad" (the source or an
    option), "device" (OpenCL), "failed" (an image that cannot be written, as
    on a read-only or full disk: not the source's fault); anything else is raised
    and retried by Dask.  Once OUTPUT_GIVE_UP images have failed to be written
    and none was written, the task's remaining views are recorded "failed" with that error
    instead of being rendered; later tasks of that folder on this worker give up
    after one failed write.
    """
    from clrt.output import OURS, file_state, render_writer, write_image
    from clrt.renderer.path import file_image, path_channels
    from clrt.scene.render_setup import render_camera, render_lights, turntable

    worker = _worker_address()
    folder = Path(job["folder"])
    base = {"source": job["source"], "views": job["count"], "key": job["key"], "worker": worker,
            "device": None}
    records = []

    def fail(views, exc, started):
        status = ("failed" if isinstance(exc, OutputError) else "bad" if isinstance(exc, InputError)
                  else "device" if isinstance(exc, DeviceError) else "failed")
        message = f"{exc}".splitlines()[0] if str(exc) else type(exc).__name__
        for view in views:
            records.append({**base, "path": job["paths"][view], "view": view, "status": status,
                            "error": message, "seconds": time.perf_counter() - started})

    started = time.perf_counter()
    bit_depth = job.get("bit_depth")
    try:
        # the format of the task's frames (one suffix for all), and what it needs (OpenEXR)
        writer, depth = render_writer(folder / job["paths"][job["views"][0]], bit_depth)
        guides = writer.holds(channels="named")   # .exr: the path tracer's albedo and normal, as clrt render's
        with device_lock():
            renderer, own = _scene_entry(job["source"], job["scene"], job["accel"], job["builder"],
                                         job["leaf_size"])
        base["device"] = renderer.device
        camera = render_camera(renderer.scene, **job["camera"])
    except ClrtError as exc:
        fail(job["views"], exc, started)
        return records
    except Exception as exc:   # noqa: BLE001
        if _is_device_error(exc):
            fail(job["views"], DeviceError(f"OpenCL error: {exc}"), started)
            return records
        raise

    # Each image is encoded and written in a thread while the next views render
    # (zlib lets go of the GIL); at most BATCH_IMAGE_WRITERS wait, and records
    # keep the views' order: a view's record goes in once its file is written.
    pending = deque()       # (view, camera, started, future) in view order
    writes = {"ok": 0, "failed": 0, "error": None}   # error: why the rest is given up
    images = str(folder / Path(job["paths"][job["views"][0]]).parent)
    known_unwritable = images in _STATE.unwritable

    def not_written(exc):
        if isinstance(exc, OutputError):
            writes["failed"] += 1
            limit = 1 if known_unwritable else OUTPUT_GIVE_UP
            if not writes["ok"] and writes["failed"] >= limit and writes["error"] is None:
                writes["error"] = exc
                _STATE.unwritable.add(images)

    def finish_one():
        view, cam, started, written = pending.popleft()
        try:
            written.result()
        except ClrtError as exc:
            fail([view], exc, started)
            not_written(exc)
            return
        writes["ok"] += 1
        _STATE.unwritable.discard(images)
        records.append({**base, "path": job["paths"][view], "view": view, "status": "done",
                        "seconds": time.perf_counter() - started, "camera": _camera_record(cam)})

    def finish_all():
        while pending:
            finish_one()

    with ThreadPoolExecutor(BATCH_IMAGE_WRITERS, thread_name_prefix="clrt-write") as writers:
        for i, view in enumerate(job["views"]):
            if writes["error"] is not None:   # nothing of this task can be written: stop rendering
                finish_all()
                fail(job["views"][i:], writes["error"], time.perf_counter())
                return records
            out = folder / job["paths"][view]
            replace = view in job["replace"]
            if not replace and file_state(out) == OURS:
                finish_all()
                # written by an earlier attempt of this task (its worker died): done, not rendered now
                records.append({**base, "path": job["paths"][view], "view": view, "status": "done",
                                "seconds": 0.0, "camera": _camera_record(turntable(camera, view, job["count"])),
                                "note": "found"})
                continue
            started = time.perf_counter()
            try:
                cam = turntable(camera, view, job["count"])
                try:
                    out.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise OutputError(f"cannot create {out.parent}: {exc.strerror or exc}") from None
                with device_lock():
                    renderer.set_lights(render_lights(renderer.scene.bounds, cam, own, job["lights"],
                                                      renderer.scene.integrator))
                    # 8-bit: the kernel's own sRGB encoding; 16-bit and float: made of the linear image
                    frame = renderer.render(cam, linear=depth != "8-bit")
            except ClrtError as exc:
                finish_all()
                fail([view], exc, started)
                not_written(exc)
                continue
            except Exception as exc:   # noqa: BLE001
                finish_all()
                if _is_device_error(exc):
                    fail(job["views"][i:], DeviceError(f"OpenCL error: {exc}"), started)
                    return records
                raise
            # a replaced view's file was judged when the batch was planned (clrt.batch.engine._plan)
            # the image as clrt render writes it: 16-bit PNGs get the exposure, EXR files the guides
            image = file_image(frame, depth, renderer.scene.exposure)
            channels = path_channels(frame) if guides else None
            pending.append((view, cam, started, writers.submit(write_image, image, out, force=job["force"] or replace,
                                                               bit_depth=bit_depth, channels=channels)))
            while len(pending) > (0 if known_unwritable and not writes["ok"] else BATCH_IMAGE_WRITERS):
                finish_one()
        finish_all()
    return records


def device_info() -> dict:
    """This worker's OpenCL device, for reports: its label and, where the driver
    tells (NVIDIA's cl_nv_device_attribute_query), its PCI bus id."""
    from clrt.device.context import create_context, device_label
    _, queue = create_context(_STATE.device)
    device = queue.device
    try:
        bus = f"{device.pci_domain_id_nv:04x}:{device.pci_bus_id_nv:02x}:{device.pci_slot_id_nv:02x}"
    except Exception:   # noqa: BLE001 -- not NVIDIA, or an older driver
        bus = "-"
    return {"device": device_label(device), "pci": bus, "spec": _STATE.device}


def _is_device_error(exc: BaseException) -> bool:
    import pyopencl as cl
    return isinstance(exc, (cl.Error, MemoryError))


def _camera_record(camera) -> dict:
    """The camera as JSON: exact floats, so ``clrt render --eye ... --target ...`` repeats it."""
    return {"eye": [float(x) for x in camera.eye], "target": [float(x) for x in camera.target],
            "up": [float(x) for x in camera.up], "fov": float(camera.fov),
            "width": int(camera.width), "height": int(camera.height)}


# --------------------------------------------------------------------------- ray chunks

#: One chunk's closest hits, as one array (the fields of clrt.Hits).
HITS = np.dtype([(name, f.dtype, f.item_shape) for name, f in CLOSEST_FIELDS.items()])

def _accel(mesh, token: str, options: dict, device: str | None):
    device = device if device is not None else _STATE.device
    key = (token, tuple(sorted(options.items())), device)

    def make():
        from clrt.query import Accel
        return Accel(mesh, device=device, **options)

    return _cached(_STATE.accels, key, make)


def hit_records(fields) -> np.dtype:
    """The record dtype of a chunk's closest hits: HITS with only ``fields``."""
    return HITS if fields is None else np.dtype([(name, HITS.fields[name][0]) for name in HITS.names
                                                 if name in fields])


def trace_chunk(origins, directions, tmin, tmax, *, mesh, mesh_token, options, device, cull, query,
                fields=None):
    """One chunk of rays against ``mesh`` on this worker's device: a structured
    array (``hit_records(fields)``) for "trace", an (n,) bool array for "occluded"."""
    with device_lock():
        accel = _accel(mesh, mesh_token, options, device)
        if query == "occluded":
            return accel.any_hit(origins, directions, tmin=_row(tmin), tmax=_row(tmax), cull=cull)
        hits = accel.trace(origins, directions, tmin=_row(tmin), tmax=_row(tmax), cull=cull, fields=fields)
    dtype = hit_records(fields)
    out = np.empty(len(origins), dtype)
    for name in dtype.names:
        out[name] = getattr(hits, name)
    return out


def _row(value):
    """A chunk of per-ray limits, or the scalar limit as given."""
    return value if np.ndim(value) == 0 else np.asarray(value)
