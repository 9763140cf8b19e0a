"""Device objects shared by threads.

An :class:`~clrt.query.accel.Accel` or a :class:`~clrt.renderer.Renderer`
keeps per-call state on the host and the device -- kernel objects whose
arguments are set and then enqueued (two steps, not atomic across threads),
chunk and tile buffers reused from call to call, a pool of result blocks.  Its
public methods therefore take turns on a per-object lock (:func:`one_at_a_time`):
two threads calling ``trace`` on one Accel get each their own answers, as
serial calls would, one after the other (the device serves one queue in order
anyway).  Objects that share a device scene (``Accel.from_renderer``) share
the renderer's lock, so a refit waits for the queries in flight.  Threads
with their own objects do not wait for each other on the host.
"""

from __future__ import annotations

import functools


def one_at_a_time(method):
    """Decorate a method so that calls on one object take turns on its
    ``_lock`` (a threading.RLock: a method may call another)."""
    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)
    return locked
