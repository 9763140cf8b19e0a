"""Device objects shared by threads, and the OpenCL driver across ``fork``.

Threads: an :class:`~clrt.query.accel.Accel` or a :class:`~clrt.renderer.Renderer`
keeps per-call state on the host and the device -- kernel objects whose
arguments are set and then enqueued (two steps, not atomic across threads),
chunk and tile buffers reused from call to call, a pool of result blocks.  Its
public methods therefore take turns on a per-object lock (:func:`one_at_a_time`):
two threads calling ``trace`` on one Accel get each their own answers, as
serial calls would, one after the other (the device serves one queue in order
anyway).  Objects that share a device scene (``Accel.from_renderer``) share
the renderer's lock, so a refit waits for the queries in flight.  Threads
with their own objects do not wait for each other on the host.

Processes: an OpenCL driver does not survive ``fork``.  Once a process has
listed the devices (PoCL then starts its worker threads, NVIDIA its own), a
forked child that makes a context, a buffer or a launch -- with the parent's
objects or new ones -- waits forever for threads that stayed behind in the
parent.  clrt notes which process started the driver and refuses device work
in any other with a :class:`DeviceError` rather than hang; workers should be
started with multiprocessing's "spawn" or "forkserver" method (an Accel
pickles: it is built again in the worker).
"""

from __future__ import annotations

import functools
import os

from clrt.errors import DeviceError

_driver_pid: int | None = None   # the process that started the OpenCL driver


def driver_started() -> None:
    """Note that this process has started the OpenCL driver (listed platforms
    and devices), unless a parent it was forked from did."""
    global _driver_pid
    if _driver_pid is None:
        _driver_pid = os.getpid()


def forked_after_start() -> bool:
    """Was this process forked from one that had started the driver?"""
    return _driver_pid is not None and _driver_pid != os.getpid()


def check_process() -> None:
    """DeviceError when the driver was started by a process this one was forked from."""
    if forked_after_start():
        raise DeviceError(
            f"OpenCL was started in process {_driver_pid} before it forked this one (pid {os.getpid()}), "
            "and a driver does not survive fork: start workers with multiprocessing's 'spawn' or "
            "'forkserver' method (an Accel pickles), or start OpenCL only in the workers")


def one_at_a_time(method):
    """Decorate a method so that calls on one object take turns on its
    ``_lock`` (a threading.RLock: a method may call another); the process
    is checked first (a lock copied by fork while held would never open)."""
    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        check_process()
        with self._lock:
            return method(self, *args, **kwargs)
    return locked
