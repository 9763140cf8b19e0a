"""What a batch watches while its tasks run (clrt.batch.engine._execute): the
tasks' run logs, workers that never come up, and tasks that hang.

**Run logs.**  Each task notes in a file of its own under the output folder
(RUN_LOGS, removed when the batch ends) a line ``s ADDRESS`` when it starts on
the worker at ADDRESS and a line ``e`` when it ends, returning or raising
(clrt.batch.worker.render_task).  A start with no end is a run that its
worker's death cut short, or a run still going on.

**Workers that never come up** (:class:`Watchdog`): no worker up for
BATCH_NO_WORKER_TIMEOUT seconds stops the batch.

**Tasks that hang** (:class:`HangWatch`): a task that runs far past the
others -- a driver call that never returns, a deadlock -- or, before any frame
has finished, past an absolute bound, is cancelled, its worker restarted and
the task submitted again.
"""

from __future__ import annotations

import os
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

from clrt.config import (BATCH_FIRST_TASK_RAY_SECONDS, BATCH_FIRST_TASK_SETUP, BATCH_HANG_FACTOR,
                         BATCH_HANG_FLOOR, BATCH_NO_WORKER_TIMEOUT)

#: Under the output folder: one run log per task, while the batch runs.
RUN_LOGS = ".clrt-runs"
#: How a batch stopped by its watchdog explains its frames: the start of their
#: error, one line for the whole batch.
NO_WORKER = "no worker stayed up for"
#: Seconds between looks at the scheduler and the run logs while no task ends.
CHECK_SECONDS = 1.0


class NoWorkers(Exception):
    """The watchdog's verdict: tasks are left and no worker came up (its text says why)."""


@dataclass(frozen=True)
class Hung:
    """A task found running far past the others: ``seconds`` since the batch saw
    it start, over ``limit``, on the worker at ``worker`` (None if unknown);
    ``rule``: how the limit was set, in words (HangWatch.limit)."""

    key: str
    seconds: float
    limit: float
    worker: str | None
    rule: str = ""


def completed(done, watchdog, hangs=None):
    """The futures of ``done`` (distributed.as_completed) as they end, and a
    :class:`Hung` for each task that ``hangs`` (a HangWatch) finds hung; both
    watchers are asked while no future is ready.  NoWorkers from the watchdog
    ends the batch."""
    while not done.is_empty():
        if done.has_ready():
            watchdog.alive()
            yield next(done)
        else:
            watchdog.check()
            if hangs is not None:
                yield from hangs.check()
            time.sleep(0.05)


class Watchdog:
    """Stops a batch whose tasks wait for workers that never come up.

    A worker process that dies while it starts -- in DevicePlugin.setup, say, a
    driver that crashes when a context is made -- is restarted by its nanny for
    ever, and no task is charged with its deaths (it never ran one): the batch
    would wait for ever; and a --scheduler cluster without workers would wait
    until Ctrl-C.  A worker is up once it has set up its device (it logs the
    batch's token under READY_TOPIC) and while it stays connected; a task that
    ends shows one too.  With no worker up for BATCH_NO_WORKER_TIMEOUT
    seconds, the batch stops, on a local cluster or a --scheduler one alike."""

    def __init__(self, client, token: str, local: bool):
        from clrt.batch.worker import READY_TOPIC
        self.client, self.token, self.local, self.topic = client, token, local, READY_TOPIC
        self.up_since = self.checked = time.monotonic()
        self.joins_seen: set = set()
        self.joins = 0     # workers that joined the scheduler since one was last up
        try:
            self._joins()  # those before the batch are not counted
        except Exception:   # noqa: BLE001 -- the scheduler gone: the tasks come back cancelled
            pass

    def alive(self) -> None:
        self.up_since = time.monotonic()
        self.joins = 0

    def check(self) -> None:
        now = time.monotonic()
        if now - self.checked < CHECK_SECONDS:
            return
        self.checked = now
        try:   # the scheduler's event logs are read only while no worker is known to be up
            connected = set(self.client.nthreads())
            if connected and connected & {msg.get("worker") for _, msg in self.client.get_events(self.topic)
                                          if isinstance(msg, dict) and msg.get("token") == self.token}:
                self.alive()
                return
            self.joins += self._joins()
        except Exception:   # noqa: BLE001 -- the scheduler gone: the tasks come back cancelled
            return
        limit = BATCH_NO_WORKER_TIMEOUT
        if now - self.up_since < limit:
            return
        again = "once the device works"
        # Workers that joined in the window were restarted: a crash loop, even
        # if one of them happens to be connected (and starting) right now.
        if self.joins:
            why = (f"every worker process died while starting its device ({self.joins} start(s); "
                   "a crash in the OpenCL driver?)")
        elif connected:
            why = (f"{len(connected)} worker process(es) connected but never finished setting up their device "
                   "(a hang in the OpenCL driver?)")
        elif self.local:
            why = "no worker process connected to the scheduler (each died while starting?)"
        else:
            why, again = "the scheduler has no workers (docs/distributed.md: starting them)", "once it has workers"
        raise NoWorkers(f"{NO_WORKER} {limit:g} s: {why}; finished images are kept: run the same command again "
                        f"{again}")

    def _joins(self) -> int:
        """Workers that joined the scheduler since the last call (its "all" events)."""
        new = 0
        for stamp, msg in self.client.get_events("all"):
            if isinstance(msg, dict) and msg.get("action") == "add-worker":
                mark = (stamp, msg.get("worker"))
                if mark not in self.joins_seen:
                    self.joins_seen.add(mark)
                    new += 1
        return new


class HangWatch:
    """Finds tasks that hang: a worker stuck in a task -- a driver call that never
    returns, a deadlock -- stays connected and up, so neither Dask nor the
    watchdog would ever end the batch.

    A task is running from the first look that finds a start without an end in
    its run log (once a second, while no task ends; a start more -- Dask ran it
    again after a worker died -- starts the clock again) and hangs once it has
    run longer than BATCH_HANG_FACTOR x the median seconds of the frames
    rendered so far x its views, and at least BATCH_HANG_FLOOR.  With no
    frame rendered yet there is nothing to compare with: the limit is then
    absolute, BATCH_FIRST_TASK_SETUP plus BATCH_FIRST_TASK_RAY_SECONDS per
    camera ray of its views (clrt/config.py says why), so that a batch whose
    every task hangs from the start ends too.  ``timeout`` (--task-timeout),
    when given, replaces that bound and caps the median's limit."""

    def __init__(self, logs: Path | None, live, timeout: float | None = None):
        self.logs, self.live = logs, live   # live(): {key: (views, camera rays a view)} of the tasks not yet ended
        self.timeout = timeout
        self.frames: list = []              # seconds of each frame rendered in this batch
        self.running: dict = {}             # key -> (starts, when first seen running)
        self.checked = time.monotonic()

    def finished(self, records) -> None:
        """Frames of a task that ended: those rendered now set the median."""
        self.frames += [r["seconds"] for r in records
                        if r.get("status") == "done" and r.get("note") != "found" and r.get("seconds")]

    def limit(self, views: int, rays: int) -> tuple[float, str]:
        """(seconds, the rule that gave them in words) a task of ``views`` views of
        ``rays`` camera rays each may run before it counts as hung."""
        if self.frames:
            limit = max(BATCH_HANG_FACTOR * statistics.median(self.frames) * max(views, 1), BATCH_HANG_FLOOR)
            rule = f"{BATCH_HANG_FACTOR:g} x the median frame time per view, at least {BATCH_HANG_FLOOR:g} s"
        else:
            limit = BATCH_FIRST_TASK_SETUP + BATCH_FIRST_TASK_RAY_SECONDS * max(views, 1) * rays
            rule = (f"no frame had finished: {BATCH_FIRST_TASK_SETUP:g} s for set-up and "
                    f"{BATCH_FIRST_TASK_RAY_SECONDS * 1e6:g} us per camera ray; --task-timeout (task_timeout=) "
                    "sets another")
        if self.timeout is not None and (self.timeout < limit or not self.frames):
            return self.timeout, "the task timeout given"
        return limit, rule

    def check(self) -> list:
        """The tasks found hung since the last look (:class:`Hung`), each once."""
        now = time.monotonic()
        if self.logs is None or now - self.checked < CHECK_SECONDS:
            return []
        self.checked = now
        try:
            started = set(os.listdir(self.logs))   # a task's log appears when it starts
        except OSError:
            return []
        hung = []
        for key, (views, rays) in self.live().items():
            if key not in started:
                continue
            starts, ends, worker = read_log(self.logs, key)
            if starts <= ends:
                self.running.pop(key, None)
                continue
            seen = self.running.get(key)
            if seen is None or seen[0] != starts:
                self.running[key] = (starts, now)
                continue
            limit, rule = self.limit(views, rays)
            if now - seen[1] > limit:
                del self.running[key]
                hung.append(Hung(key, now - seen[1], limit, worker, rule))
        return hung


# --------------------------------------------------------------------------- run logs

def run_logs(folder: Path) -> Path | None:
    """The folder of the tasks' run logs, without the logs of a batch that
    crashed (the folder lock says no other batch uses them); None if it cannot
    be made (the tasks then count as never running)."""
    logs = folder / RUN_LOGS
    remove_run_logs(logs)
    try:
        logs.mkdir(exist_ok=True)
    except OSError:
        return None
    return logs


def remove_run_logs(logs: Path) -> None:
    """The tasks' run logs, and their folder once empty: clrt removes only what it wrote."""
    try:
        for log in logs.glob("clrt-render-*"):
            log.unlink()
        logs.rmdir()
    except OSError:
        pass


def read_log(logs: Path | None, key) -> tuple[int, int, str | None]:
    """(starts, ends, the worker of the last start) in task ``key``'s run log."""
    if logs is None:
        return 0, 0, None
    try:
        lines = (logs / str(key)).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return 0, 0, None
    starts = [line[1:].strip() for line in lines if line.startswith("s")]
    return len(starts), sum(line.startswith("e") for line in lines), (starts[-1] or None) if starts else None


def runs(logs: Path | None, key) -> int:
    """Runs of task ``key`` that its worker's death cut short: starts with no end."""
    starts, ends, _ = read_log(logs, key)
    return max(starts - ends, 0)
