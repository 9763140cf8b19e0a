"""Many frames of many sources on the workers of a Dask cluster.

    >>> outputs = clrt.batch.render(["meshes/"], "out", views=36, width=640, height=480)
    >>> [o.path for o in outputs if o.status == "done"]

Every image is written atomically under a name that depends only on its source,
view and format (``OUT/<source-stem>/view-0007.png``; ``--format``: any image
format of clrt.output.WRITERS, such as .exr) and recorded in the folder's
manifest (clrt.batch.manifest), with the record of its SHA-256 beside it
(clrt.output).  Running the same batch again renders only what is missing, no
longer exactly what clrt wrote, or made with other settings, so a batch
stopped by Ctrl-C, a crash or a lost worker is finished by running it again; a
task whose worker dies is retried on another by Dask, one that hangs is
cancelled and retried, before any frame has finished too (clrt.batch.watch).
"""

from __future__ import annotations

import dataclasses

import sys
import time
import uuid
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

from clrt import checks
from clrt.batch import watch
from clrt.batch.cluster import (cpu_cores, dashboard_link, default_workers, keep_lost_workers, require_dask,
                                start_local_cluster)
from clrt.batch.jobs import Source, camera_rays, expand_sources, output_path, plan_tasks, settings_key
from clrt.batch.manifest import FolderLock, Manifest
from clrt.config import (BATCH_CACHE_SCENES, BATCH_FORMAT, BATCH_HANG_RETRIES, BATCH_KILLED_RESUBMITS,
                         BATCH_LOST_RESUBMITS, BATCH_TASK_RETRIES, DEFAULT_ACCEL, DEFAULT_BUILDER,
                         DEFAULT_LEAF_SIZE, MAX_VIEWS, MAX_WORKERS)
from clrt.errors import InputError, OutputError
from clrt.options import check_api
from clrt.scene.render_setup import CAMERA_OPTIONS, SCENE_OPTIONS

#: Status of an output: rendered now ("done"), before ("skipped": also an image a
#: retried task found written by its first attempt), or why not.
STATUSES = ("done", "skipped", "bad", "device", "failed")


class ClusterLost(ConnectionError):
    """The Dask scheduler, or the connection to it, went away during a batch: its
    tasks came back cancelled.  An OSError, as distributed's CommClosedError is:
    ``clrt batch render`` reports both as "lost the Dask cluster" (exit 3).  What
    finished is recorded; running the same batch again renders the rest."""


@dataclass(frozen=True)
class Output:
    """One row of a batch's table: an image (or a source that gave none)."""

    path: str | None        # absolute path of the image; None for a bad source
    source: str
    view: int | None
    seconds: float          # render and write time on the worker (0 when skipped)
    worker: str | None      # address of the worker that made it
    status: str = "done"    # see STATUSES
    error: str = ""
    redone: str = ""        # "done" again: why its earlier image was not kept (a key of REDONE)


@dataclass
class Summary:
    """What a batch did: rows, wall time, frames rendered per worker."""

    outputs: list
    seconds: float          # wall time of the whole batch, cluster start included
    workers: int
    render_seconds: float = 0.0   # from the first job sent to the last result

    @property
    def frames_per_second(self) -> float:
        return self.rendered / self.render_seconds if self.render_seconds > 0 else 0.0

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outputs)

    @property
    def rendered(self) -> int:
        return self.count("done")

    def redone(self) -> dict:
        """Frames rendered again because their earlier image was missing or had
        changed since written, by reason (REDONE's words)."""
        counts = Counter(o.redone for o in self.outputs if o.status == "done" and o.redone)
        return {REDONE[k]: counts[k] for k in REDONE if counts[k]}

    def per_worker(self) -> dict:
        return dict(sorted(Counter(o.worker for o in self.outputs if o.status == "done").items()))

    def bad_sources(self) -> list[str]:
        """One line per source that gave no image, or an error, first error first;
        the frames of a source that failed otherwise (images that could not be
        written, tasks that raised) give one line: the first error and how many."""
        lines, seen, failed = [], {}, Counter()
        for o in self.outputs:
            if o.status not in ("bad", "device", "failed"):
                continue
            if o.status == "device" and o.error.startswith(watch.NO_WORKER):   # the batch's, not the source's
                if (None, o.error) not in seen:
                    seen[None, o.error] = len(lines)
                    lines.append(o.error)
                continue
            key = (o.source, "failed") if o.status == "failed" else (o.source, o.error)
            failed[key] += o.status == "failed"
            if key not in seen:
                seen[key] = len(lines)
                lines.append(o.error if o.error.startswith(o.source) else f"{o.source}: {o.error}")
        for key, n in failed.items():
            if n > 1:
                lines[seen[key]] += f" ({n} frames failed)"
        return lines

    def exit_code(self) -> int:
        """0 all done; 3 device trouble; 2 bad sources (the rest done); 1 other failures."""
        statuses = {o.status for o in self.outputs}
        if "device" in statuses:
            return 3
        if "failed" in statuses:
            return 1
        if "bad" in statuses:
            return 2
        return 0


def render(sources, out_dir, views: int = 1, *, client=None, workers: int | None = None,
           device: str | None = None, accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER,
           leaf_size: int = DEFAULT_LEAF_SIZE, lights=None, force: bool = False, progress: bool = False,
           log=None, format: str = BATCH_FORMAT, bit_depth: int | None = None, task_timeout: float | None = None,
           **options) -> list[Output]:
    """Render ``views`` turntable views of every source into ``out_dir``.

    ``sources``: mesh and scene files, folders, glob patterns (one job per file).
    ``options``: the scene and camera options of ``clrt render`` (width, height,
    eye, target, up, fov, color, ambient, diffuse, specular, shininess, flat,
    background, samples, max_depth); ``lights``: light positions.  ``client``: a
    ``distributed.Client``; without one, a local cluster of ``workers``
    processes (default: one per GPU, else one per two CPU cores) runs the batch.
    ``progress``: a progress bar on stderr; ``log``: called with informational
    lines (the dashboard link).  ``format``: the frames' format, an image
    suffix without its dot (png, exr, tif, ...: clrt.output.FORMAT_NAMES);
    ``bit_depth``: 8 or 16 (16-bit PNG), None for the format's own (8-bit;
    linear float32 for exr).  ``task_timeout``: seconds a task (up to
    BATCH_VIEWS_PER_TASK views of a source) may run before it counts as hung
    and is cancelled and retried; default: a bound from the task's views and
    image size until a frame has finished, then 10 x the median frame time
    (clrt.batch.watch.HangWatch), which ``task_timeout`` also caps.  Returns
    one :class:`Output` per image and per bad source; :func:`run` also returns
    the summary.
    """
    return run(sources, out_dir, views, client=client, workers=workers, device=device, accel=accel,
               builder=builder, leaf_size=leaf_size, lights=lights, force=force, progress=progress,
               log=log, format=format, bit_depth=bit_depth, task_timeout=task_timeout, **options).outputs


def run(sources, out_dir, views: int = 1, *, client=None, workers: int | None = None, device=None,
        accel=DEFAULT_ACCEL, builder=DEFAULT_BUILDER, leaf_size=DEFAULT_LEAF_SIZE, lights=None,
        force=False, progress=False, log=None, format=BATCH_FORMAT, bit_depth=None, task_timeout=None,
        **options) -> Summary:
    """:func:`render`, returning the :class:`Summary` (outputs, time, per-worker counts)."""
    settings = _check_options(views, accel, builder, leaf_size, lights, options)
    suffix = _frame_format(format, bit_depth, settings)
    if workers is not None:
        checks.integer("workers", workers, 1, MAX_WORKERS)
    if task_timeout is not None:
        task_timeout = checks.number("task_timeout", task_timeout, gt=0)
    if isinstance(sources, (str, Path)):
        sources = [sources]
    found = expand_sources(sources)
    folder = _output_folder(out_dir)
    started = time.perf_counter()
    with FolderLock(folder):
        manifest = Manifest(folder, force)
        outputs, pending, redone = _plan(found, folder, manifest, views, settings, suffix, force)
        manifest.write()
        if not pending:
            return Summary(outputs, time.perf_counter() - started, 0)
        require_dask()
        cluster = own_client = None
        with ExitStack() as kept:   # keep_lost_workers() while a local cluster lives
            try:
                if client is None:
                    n_workers, jobs = _local_workers(workers, device, log, lambda count: _jobs(
                        pending, folder, views, settings, force, count, suffix))
                    kept.enter_context(keep_lost_workers())
                    cluster = start_local_cluster(n_workers, device)
                    from distributed import Client
                    client = own_client = Client(cluster)
                else:
                    n_workers = len(client.scheduler_info().get("workers", {}))
                    if not n_workers and log:
                        log(f"the scheduler has no workers yet: the jobs wait {watch.BATCH_NO_WORKER_TIMEOUT:g} s "
                            "for one")
                    jobs = _jobs(pending, folder, views, settings, force, n_workers, suffix)
                link = dashboard_link(client)
                if link and log:
                    log(f"dashboard: {link}")
                sent = time.perf_counter()
                outputs += _execute(client, jobs, folder, manifest, device, progress, local=cluster is not None,
                                    redone=redone, task_timeout=task_timeout)
                render_seconds = time.perf_counter() - sent
            finally:
                manifest.write()
                if own_client is not None:
                    own_client.close()
                if cluster is not None:
                    cluster.close()
    return Summary(outputs, time.perf_counter() - started, n_workers, render_seconds)


def _local_workers(asked: int | None, device, log, make_jobs) -> tuple[int, list]:
    """(worker processes, jobs) of a local cluster: ``asked`` (default: one per
    GPU, else one per two cores), but never more than the CPU cores -- a worker
    is a process that keeps at least one core busy, and 64 of them on 2 cores
    took 92 s for a frame that 2 render in 1.7 s -- nor than the tasks (cut for
    that many workers first).  A note in one line when ``asked`` is cut."""
    cores = cpu_cores()
    count = min(asked or default_workers(device), cores)
    jobs = make_jobs(count)
    count = max(1, min(count, len(jobs)))
    if asked is not None and count < asked and log:
        log(f"{count} worker(s) instead of {asked}: {cores} CPU core(s), {len(jobs)} task(s)")
    return count, jobs


def _check_options(views, accel, builder, leaf_size, lights, options) -> dict:
    """Every option checked before any worker starts; the settings that decide an image."""
    checks.integer("views", views, 1, MAX_VIEWS)
    checks.accel_options(accel, builder, leaf_size)
    # Checked here once, by clrt render's option table (clrt.options: the same
    # rules and messages as the command line and clrt.render, a misspelt name's
    # hint included), rather than failing every source the same way on the workers.
    check_api({**options, "accel": accel, "builder": builder, "leaf_size": leaf_size, "lights": lights},
              "batch render")
    unknown = set(options) - set(SCENE_OPTIONS) - set(CAMERA_OPTIONS)
    if unknown:   # options of clrt render that a batch's frames do not take
        raise InputError(f"batch render does not take {', '.join(sorted(unknown))}")
    scene = {k: _plain(options.get(k)) for k in SCENE_OPTIONS}
    scene["flat"] = bool(scene["flat"])
    camera = {k: _plain(options.get(k)) for k in CAMERA_OPTIONS}
    return {"scene": scene, "camera": camera, "lights": _plain(lights) or None, "accel": accel,
            "builder": builder, "leaf_size": int(leaf_size), "views": int(views)}


def _frame_format(format, bit_depth, settings: dict) -> str:
    """The frames' suffix, checked with ``bit_depth`` -- and the format's optional
    package -- before any worker starts (clrt.output.render_writer).  A 16-bit
    depth joins the settings that decide an image: the same file name at
    another depth is rendered again."""
    from clrt.output import check_bit_depth, format_writer, render_writer
    writer = format_writer(format, "format")
    render_writer(f"view-NNNN{writer.suffix}", check_bit_depth(bit_depth, "bit_depth"))
    if bit_depth == 16:
        settings["bit_depth"] = 16
    return writer.suffix


def _plain(value):
    """Tuples of floats and plain numbers, as they travel in tasks and JSON; a
    clrt.Light as the dict of its fields (Light.of makes it again on the worker)."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return [_plain(v) for v in value] if not hasattr(value, "item") else value.item()


def _output_folder(out_dir) -> Path:
    if isinstance(out_dir, str) and not out_dir.strip():   # Path('') is the current folder
        raise OutputError(f"out_dir must name a folder, got {out_dir!r}")
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"cannot write into {folder}: it is not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {folder}: {exc.strerror or exc}") from None
    return folder.resolve()


#: Why an existing frame is rendered again (Output.redone): its file was gone,
#: or is no longer the one clrt wrote (cut short, edited, replaced, unreadable).
REDONE = {"missing": "missing", "changed": "changed since written"}


def _plan(found: list[Source], folder: Path, manifest: Manifest, views: int, settings: dict, suffix: str,
          force: bool = False):
    """Rows for bad arguments and finished images, per source the views to
    render, and why a frame recorded done is rendered again (REDONE, by path).

    The files decide, by their content -- clrt.output.file_state, the rule of
    clrt render's overwrites: a frame is done when its file is exactly what
    clrt wrote (the record beside it holds its SHA-256) with the settings of
    this batch (the manifest's key); it is rendered again when it is missing,
    changed since written, or made with other settings.  A file where a frame
    goes that clrt did not write and the manifest does not know is not the
    batch's: OutputError before anything is rendered, unless ``force``."""
    from clrt.output import CHANGED, FOREIGN, NOT_A_FILE, OURS, file_state
    outputs, pending, redone, foreign = [], [], {}, []
    for source in found:
        if source.error:
            manifest.add({"path": None, "source": source.path, "view": None, "status": "bad",
                          "error": source.error})
            outputs.append(Output(None, source.path, None, 0.0, None, "bad", source.error))
            continue
        manifest.drop_bad(source.path)
        key = settings_key(source.path, settings)
        todo, replace = [], set()
        for view in range(views):
            rel = output_path(source.name, view, suffix)
            path = folder / rel
            record = manifest.get(rel)
            recorded = record is not None and record.get("status") == "done"
            state = file_state(path)
            if state == NOT_A_FILE:
                raise OutputError(f"cannot write {path}: it is not a regular file")
            if state == OURS:
                if recorded and record.get("key") == key:
                    outputs.append(Output(str(path), source.path, view, 0.0, record.get("worker"), "skipped"))
                    continue
                if record is None:   # written, and the command died before the manifest was
                    manifest.add({"path": rel, "source": source.path, "view": view, "views": views,
                                  "status": "done", "key": key, "note": "found"})
                    outputs.append(Output(str(path), source.path, view, 0.0, None, "skipped"))
                    continue
                replace.add(view)                # other settings, or recorded failed
            elif state == CHANGED or (state == FOREIGN and recorded):
                # not the bytes clrt wrote: a frame of this batch's that was cut
                # short, edited or replaced (or whose record is gone)
                replace.add(view)
                redone[rel] = "changed"
            elif state == FOREIGN:
                if not force:
                    foreign.append(path)
                    continue
                replace.add(view)
            elif recorded:
                redone[rel] = "missing"
            todo.append(view)
        if todo:
            pending.append((source, key, todo, replace))
    if foreign:
        others = f" (and {len(foreign) - 1} other frame file(s) of this batch)" if len(foreign) > 1 else ""
        raise OutputError(f"{foreign[0]} exists and was not written by clrt{others}; pass --force (-f; force=True "
                          "in Python) to replace it, or choose another -o")
    return outputs, pending, redone


def _jobs(pending: list, folder: Path, views: int, settings: dict, force: bool, workers: int,
          suffix: str) -> list[dict]:
    """The tasks' arguments: plain data (paths, options), never device state."""
    jobs = []
    for source, key, todo, replace in pending:
        for task in plan_tasks(source, todo, replace, workers, len(pending)):
            jobs.append({
                "source": source.path, "name": source.name, "views": task.views, "replace": task.replace,
                "paths": {v: output_path(source.name, v, suffix) for v in task.views}, "count": views,
                "folder": str(folder), "scene": settings["scene"], "camera": settings["camera"],
                "lights": settings["lights"], "accel": settings["accel"], "builder": settings["builder"],
                "leaf_size": settings["leaf_size"], "bit_depth": settings.get("bit_depth"), "force": force,
                "key": key})
    return jobs


@dataclass
class _Task:
    """A job as submitted: its images before the batch (see _remove_unrecorded) and
    how often it was submitted again, after its result was lost (``lost``) or
    after its workers died while it waited (``killed``)."""

    job: dict
    files: dict
    rays: int = 0           # camera rays of one of its views, as known before rendering (jobs.camera_rays)
    lost: int = 0
    killed: int = 0
    deaths: int = 0         # of the workers it was sent to, in all its submissions
    ran: int = 0            # of those deaths, while it was running
    crashed: bool = False   # running at allowed-failures + 1 of them: it is the crash
    hung: int = 0           # times it was found hung, cancelled and its worker restarted


def _execute(client, jobs: list, folder: Path, manifest: Manifest, device, progress: bool,
             local: bool = False, redone: dict | None = None, task_timeout: float | None = None) -> list[Output]:
    """Run the jobs, record each finished one; Ctrl-C cancels what is left.

    A worker's death: Dask's scheduler charges it to every task it had sent to
    that worker -- the one running and those waiting in the worker's queue --
    and fails a task (KilledWorker) once allowed-failures + 1 of its workers
    died.  A healthy task queued behind one that crashes its worker each time
    would be failed with it.  So each task notes in its run log (clrt.batch.watch) when
    it starts and ends, and clrt applies Dask's rule to the deaths a task could
    have caused, those while it was running: a task failed so is reported once
    it was running at allowed-failures + 1 deaths, in all its submissions; until
    then it is submitted again as a new task (BATCH_KILLED_RESUBMITS times at
    most, which bounds the deaths it waits through).

    A task that runs far past the others, or before any frame has finished
    past a bound from its views and image size, or past ``task_timeout``
    (clrt.batch.watch.HangWatch), is cancelled, its worker restarted, and it
    is submitted again, at most BATCH_HANG_RETRIES times; then its frames are
    "device"."""
    from distributed import as_completed

    from clrt.batch.worker import DevicePlugin, render_task
    token = uuid.uuid4().hex
    try:
        client.register_plugin(DevicePlugin(device, BATCH_CACHE_SCENES, ignore_interrupts=local, token=token))
    except OSError:
        # A worker died setting up its device: the scheduler keeps the plugin for
        # the other workers and the restarted ones; the watchdog sees whether any comes up.
        if getattr(client, "status", None) != "running":
            raise
    watchdog = watch.Watchdog(client, token, local)
    logs = watch.run_logs(folder)
    futures, keys = {}, {}
    handled = set()   # futures whose end was dealt with (a task submitted again has several)
    hangs = watch.HangWatch(logs, lambda: {f.key: (len(t.job["views"]), t.rays) for f, t in futures.items()
                                           if f not in handled}, task_timeout)

    def submit(task: _Task):
        job = task.job
        key = f"clrt-render-{job['name']}-{job['views'][0]:04d}-{uuid.uuid4().hex[:12]}"
        if logs is not None:
            job = {**job, "run_log": f"{watch.RUN_LOGS}/{key}"}
        future = client.submit(render_task, job, pure=False, retries=BATCH_TASK_RETRIES, key=key)
        futures[future], keys[key] = task, future
        return future

    # Each job's images as they are before any task runs (see _remove_unrecorded)
    for job in jobs:
        submit(_Task(job, {v: _file_id(folder / job["paths"][v]) for v in job["views"]},
                     camera_rays(job["source"], job["scene"], job["camera"])))
    total = sum(len(job["views"]) for job in jobs)
    bar = _progress_bar(total, progress)
    outputs = []

    def take(records):
        for record in records:
            manifest.add(record)
            status = record["status"]
            seconds = record.get("seconds") or 0.0
            path = str(folder / record["path"]) if status == "done" else None
            if status == "done" and record.get("note") == "found":
                status = "skipped"   # written by an earlier attempt of a retried task
            why = (redone or {}).get(record["path"], "") if status == "done" else ""
            outputs.append(Output(path, record["source"], record["view"], seconds, record.get("worker"),
                                  status, record.get("error", ""), why))
        hangs.finished(records)
        bar.update(len(records))
        manifest.write(force=False)

    try:
        done = as_completed(list(futures))
        for future in watch.completed(done, watchdog, hangs):
            if isinstance(future, watch.Hung):
                hung, future = future, keys.get(future.key)
                if future is None or future in handled or future.done():
                    continue
                handled.add(future)
                task = futures[future]
                _stop_hung(client, future, hung.worker)
                task.hung += 1
                if task.hung <= BATCH_HANG_RETRIES:
                    done.add(submit(task))   # on the restarted worker, or another
                else:
                    _remove_unrecorded(folder, task.job, task.files)
                    take(_hung_records(task, hung))
                continue
            if future in handled:   # cancelled when it hung
                continue
            handled.add(future)
            task = futures[future]
            job = task.job
            running = getattr(client, "status", None) == "running"
            if future.status == "finished":
                try:
                    records = future.result()
                except Exception:   # noqa: BLE001 -- lost between finishing and its fetch
                    records = None
            elif future.status == "error":
                exc = future.exception()
                if type(exc).__name__ == "KilledWorker":
                    deaths = getattr(exc, "allowed_failures", 0) + 1
                    task.deaths, task.ran = task.deaths + deaths, task.ran + watch.runs(logs, future.key)
                    task.crashed = task.ran >= deaths
                    if not task.crashed and task.killed < BATCH_KILLED_RESUBMITS and running:
                        # some of those deaths came while it waited behind a
                        # task that killed the worker: they are not its own
                        task.killed += 1
                        done.add(submit(task))
                        continue
                records = _failed_records(job, future, task)
                _remove_unrecorded(folder, job, task.files)
            else:
                records = None
            if records is None:
                # Lost with the worker that held it (another task killed that
                # worker) while the cluster runs on: submit it again.  Cancelled,
                # or the client lost the scheduler: never the frames' fault.
                if future.status in ("lost", "finished") and running and task.lost < BATCH_LOST_RESUBMITS:
                    task.lost += 1
                    done.add(submit(task))
                    continue
                raise ClusterLost(_lost_reason(client, future))
            take(records)
    except watch.NoWorkers as exc:
        for future, task in futures.items():
            if future not in handled:
                records = [{"path": task.job["paths"][v], "source": task.job["source"], "view": v,
                            "views": task.job["count"], "status": "device", "key": task.job["key"],
                            "error": str(exc), "worker": None} for v in task.job["views"]]
                _remove_unrecorded(folder, task.job, task.files)
                for record in records:
                    manifest.add(record)
                    outputs.append(Output(None, record["source"], record["view"], 0.0, None, "device",
                                          record["error"]))
    finally:
        bar.close()
        pending = [f for f in futures if not f.done()]
        if pending:
            try:
                client.cancel(pending)
            except Exception:   # noqa: BLE001 -- the scheduler may be gone already
                pass
        if logs is not None:
            watch.remove_run_logs(logs)
    return outputs


def _stop_hung(client, future, worker: str | None) -> None:
    """Cancel a hung task and restart the worker running it: a thread that never
    returns cannot be stopped, only its process, and until then the worker
    (one thread) would hold every task sent to it.  Through its nanny (always
    there on a local cluster); a worker without one is retired instead."""
    try:
        client.cancel([future])
    except Exception:   # noqa: BLE001 -- the scheduler gone: the next future says so
        pass
    if worker is None:
        return
    try:
        client.restart_workers([worker])
    except Exception:   # noqa: BLE001 -- no nanny, or the worker left already
        try:
            client.retire_workers([worker], close_workers=True)
        except Exception:   # noqa: BLE001
            pass


def _hung_records(task: _Task, hung) -> list[dict]:
    """Records of a task found hung once more than BATCH_HANG_RETRIES allow: one line, naming it."""
    job = task.job
    views = job["views"]
    which = f"view {views[0]}" if len(views) == 1 else f"views {views[0]}-{views[-1]}"
    error = (f"{job['source']}: hung: the task of {which} ran past {hung.limit:.1f} s {task.hung} times "
             f"({hung.rule}); its worker was restarted each time")
    return [{"path": job["paths"][v], "source": job["source"], "view": v, "views": job["count"],
             "status": "device", "key": job["key"], "error": error, "worker": hung.worker} for v in views]


def _lost_reason(client, future) -> str:
    """Why a task came back without a result (future.status "cancelled", "lost")."""
    status = getattr(client, "status", None)
    if status not in (None, "running", "newly-created"):
        return f"the connection to the scheduler is {status}; its tasks came back {future.status}"
    return f"its tasks came back {future.status} (the scheduler stopped or restarted?)"


def _failed_records(job: dict, future, task: _Task) -> list[dict]:
    """Records of a task that raised, or whose workers kept dying (KilledWorker)."""
    exc = future.exception()
    if exc is None:   # no error after all: cancelled, the cluster is gone
        raise ClusterLost(f"a task came back {future.status} without a result")
    name = type(exc).__name__
    status = "device" if name == "KilledWorker" else "failed"
    message = (str(exc).splitlines() or [""])[0]
    # Dask's text sends the user to worker logs that clrt does not show
    if name == "KilledWorker" and task.crashed:
        message = "the worker process running it died each time it was tried (a crash, or out of memory?)"
    elif name == "KilledWorker":
        submitted = f" in {task.killed + 1} submissions" if task.killed else ""
        message = (f"its worker processes died {task.deaths} times{submitted}, {task.ran} of them while it ran "
                   "(other tasks crashing the workers?)")
    error = f"{job['source']}: {name}: {message}" if message else f"{job['source']}: {name}"
    return [{"path": job["paths"][v], "source": job["source"], "view": v, "views": job["count"],
             "status": status, "key": job["key"], "error": error, "worker": None} for v in job["views"]]


def _file_id(path: Path):
    """What tells a file from the one written in its place (a rename makes a new inode); None if none."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size


def _remove_unrecorded(folder: Path, job: dict, files: dict) -> None:
    """Remove the images of a task that failed for good, as clrt render removes an
    image whose AOVs failed: its frames are recorded failed, so no image of theirs
    may be left to look done.  A task that raised after writing some views (and
    again when retried), or whose workers kept dying, returned no records for the
    images its attempts wrote; an image that differs from the one there before
    the batch ran is such an image.  Images that were there before stay."""
    from clrt.output import remove_written
    paths = [folder / job["paths"][v] for v in job["views"]]
    remove_written([p for p, v in zip(paths, job["views"]) if _file_id(p) not in (None, files[v])])


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress_bar(total: int, shown: bool):
    if not shown:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(total=total, unit="frame", file=sys.stderr, dynamic_ncols=True, mininterval=0.5)
