"""Where batch jobs run: a local cluster of worker processes that lives as long as
the command, or the workers of an existing Dask cluster (``--scheduler``).

The local cluster listens on the loopback interface only -- scheduler, workers,
nannies and dashboard -- so nothing is reachable from the network.  Workers are
processes (OpenCL contexts are per process) with one thread each.

Dask's own log lines (a worker's "Compute Failed" with its traceback, the
scheduler's and nannies' notes) are not shown -- by the processes of the local
cluster, and by the command's own process: every failure reaches the user as
clrt's one line per source.  Workers of a ``--scheduler`` cluster log as they
were set up to.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import signal
import threading
from contextlib import contextmanager

from clrt.config import BATCH_CONNECT_TIMEOUT, BATCH_HANDSHAKE_SLACK
from clrt.errors import ClrtError, InputError

LOOPBACK = "127.0.0.1"

#: Loggers that Dask's logging set-up gives a stderr handler, and the level that
#: silences them (above CRITICAL).
DASK_LOGGERS = ("distributed", "bokeh", "tornado")
SILENT = logging.CRITICAL + 10


def require_dask() -> None:
    """ClrtError naming the install command when Dask distributed is missing."""
    if importlib.util.find_spec("distributed") is None or importlib.util.find_spec("dask") is None:
        raise ClrtError("batch jobs need Dask: pip install 'clrt[distributed]'")


def cpu_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def default_workers(device: str | None) -> int:
    """One worker per GPU found, else one per two CPU cores (one for a 'P:D' device)."""
    kind = (device or "").strip().lower()
    if kind and kind not in ("gpu", "cpu"):
        return 1
    if kind != "cpu":
        from clrt.device.context import list_devices
        gpus = sum(d.type == "GPU" for d in list_devices())
        if gpus:
            return gpus
    return max(1, cpu_cores() // 2)


def start_local_cluster(workers: int, device: str | None = None):
    """A distributed.LocalCluster of ``workers`` processes on the loopback interface.

    On CPU devices each worker's PoCL gets its share of the cores (unless the
    environment already says), so workers do not fight over them."""
    require_dask()
    from distributed import LocalCluster

    env = {}
    share = str(max(1, cpu_cores() // workers))
    for var in ("POCL_MAX_PTHREAD_COUNT", "POCL_CPU_MAX_CU_COUNT"):
        if var not in os.environ and (device or "").strip().lower() != "gpu":
            env[var] = share
    # The scheduler's HTTP server (the dashboard when bokeh is installed, else health
    # and metrics pages) on a free loopback port: never Dask's default :8787.
    dashboard = f"{LOOPBACK}:0"
    # No memory limit: Dask would pause or restart a worker holding a large mesh
    # (clrt checks host memory itself).
    # Ctrl-C reaches every process of the terminal's group; it is the client's to
    # handle (it stops the cluster).  Worker processes started while SIGINT is
    # ignored keep ignoring it; restarted ones are told by DevicePlugin.
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=LOOPBACK,
                            scheduler_port=0, dashboard_address=dashboard, worker_dashboard_address=None,
                            silence_logs=SILENT, env=env, memory_limit=0)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


#: What clrt sets distributed.deploy.lost-worker-timeout to while its local
#: cluster runs (Dask's default: 15 s): never, in practice.
KEEP_LOST_WORKERS = "3650 days"


@contextmanager
def keep_lost_workers():
    """While the block runs, Dask's LocalCluster never closes the nanny of a
    worker that died: its nanny restarts it, however often it dies.

    15 s after each death of a worker (``distributed.deploy.lost-worker-timeout``)
    a LocalCluster closes that worker's nanny for good if no worker of that name
    is connected at that moment: meant for workers whose job went away, it hits
    a worker that a crashing task kills again and again, when it is restarting
    just then -- and a batch on one worker would then wait for ever.  Dask reads
    the setting when a worker dies, in the process that holds the cluster, so it
    is set for as long as the cluster lives."""
    import dask
    with dask.config.set({"distributed.deploy.lost-worker-timeout": KEEP_LOST_WORKERS}):
        yield


@contextmanager
def quiet_dask_logs():
    """Silence Dask's log handlers in this process while the block runs (what
    ``silence_logs`` does in a LocalCluster's processes), for the command's
    client process; restored after."""
    importlib.import_module("distributed")   # which sets up Dask's handlers
    changed = []
    for name in DASK_LOGGERS:
        for handler in logging.getLogger(name).handlers:
            changed.append((handler, handler.level))
            handler.setLevel(SILENT)
    try:
        yield
    finally:
        for handler, level in changed:
            handler.setLevel(level)


def connect(address: str):
    """A Client of the Dask scheduler at ``address`` (tcp:// or tls://); for tls://
    the certificates come from Dask's configuration (docs/distributed.md)."""
    require_dask()
    import dask
    from distributed import Client
    from distributed.security import Security

    if "://" not in address:
        address = f"tcp://{address}"
    security = None
    if address.startswith("tls://"):
        security = Security()
        if not (security.tls_ca_file and security.tls_client_cert):
            raise InputError(f"--scheduler {address}: tls:// needs certificates in Dask's configuration: "
                             "distributed.comm.tls.ca-file, .client.cert and .client.key (docs/distributed.md)")
    _probe(address)
    # The Client is made in a thread of its own with a deadline: Dask's connect
    # timeout covers opening the connection, not its handshake, so a server that
    # accepts and never answers (not a Dask scheduler) would hold it for ever.
    # A Client that fails or hangs is closed here: left open, it stayed the
    # process's default client and kept Dask's scheduler setting at
    # "dask.distributed", so a later dask.compute in the process waited on it for ever.
    result: dict = {}
    made: list = []

    class ClrtClient(Client):   # its name is the scheduler's id of it
        def start(self, **kwargs):
            made.append(self)   # before it connects: it is there to close if that fails
            return super().start(**kwargs)

    def make_client() -> None:
        try:
            with dask.config.set({"distributed.comm.timeouts.connect": f"{BATCH_CONNECT_TIMEOUT}s"}):
                result["client"] = ClrtClient(address, security=security, timeout=BATCH_CONNECT_TIMEOUT)
        except BaseException as exc:   # noqa: BLE001 -- handed to the caller's thread below
            result["error"] = exc

    maker = threading.Thread(target=make_client, name="clrt-connect", daemon=True)
    maker.start()
    maker.join(BATCH_CONNECT_TIMEOUT + BATCH_HANDSHAKE_SLACK)
    hung = maker.is_alive()
    if hung or "error" in result:
        _close_quietly(made)
    if hung:
        raise InputError(f"cannot reach the Dask scheduler at {address}: no answer within "
                         f"{BATCH_CONNECT_TIMEOUT + BATCH_HANDSHAKE_SLACK:g} s (is it a Dask scheduler?)")
    exc = result.get("error")
    if exc is None:
        return result["client"]
    if isinstance(exc, MemoryError):   # a server that is not Dask: its reply read as a frame length
        raise InputError(f"cannot reach the Dask scheduler at {address}: the server there does not speak "
                         "Dask's protocol") from None
    if isinstance(exc, (OSError, TimeoutError, ValueError, TypeError)):   # TypeError: e.g. ucx:// without ucx
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    raise exc


def _probe(address: str) -> None:
    """InputError at once where nothing listens at a tcp:// or tls:// address
    (connection refused, unknown host), or where nothing answers within
    BATCH_CONNECT_TIMEOUT: Dask's Client tries a refused port again and again
    until its timeout, so a typo in --scheduler cost 10 s before this."""
    import socket

    from distributed.comm.addressing import parse_address, parse_host_port
    try:
        scheme, location = parse_address(address)
        host, port = parse_host_port(location, 8786)   # Dask's default port
    except ValueError as exc:
        raise InputError(f"--scheduler {address}: {exc}") from None
    if scheme not in ("tcp", "tls"):
        return   # other transports (ucx, inproc): Dask connects
    try:
        socket.create_connection((host, port), timeout=BATCH_CONNECT_TIMEOUT).close()
    except ConnectionRefusedError:
        raise InputError(f"cannot reach the Dask scheduler at {address}: connection refused "
                         f"(nothing listens on port {port} of {host})") from None
    except socket.gaierror as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: unknown host {host!r} "
                         f"({exc.strerror or exc})") from None
    except TimeoutError:
        raise InputError(f"cannot reach the Dask scheduler at {address}: no answer within "
                         f"{BATCH_CONNECT_TIMEOUT:g} s") from None
    except OSError as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: {exc.strerror or exc}") from None


def _close_quietly(clients) -> None:
    """Close Clients that failed to connect (their own errors are not the story:
    the caller reports why the connection failed)."""
    for client in clients:
        try:
            client.close(timeout=BATCH_HANDSHAKE_SLACK)
        except Exception:   # noqa: BLE001
            pass


#: Seconds to wait for a scheduler's dashboard page before leaving its link out.
DASHBOARD_PROBE_SECONDS = 1.0


def dashboard_link(client) -> str | None:
    """The dashboard's address when the scheduler runs one (it needs bokeh).
    A scheduler started with --no-dashboard still lists an HTTP service (its
    health and metrics pages), so another's link is shown only if its page
    answers."""
    if importlib.util.find_spec("bokeh") is None and client.cluster is not None:
        return None   # our local cluster: only health and metrics pages without bokeh
    try:
        port = client.scheduler_info().get("services", {}).get("dashboard")
    except Exception:  # noqa: BLE001 -- only informative
        return None
    if not port:
        return None
    link = client.dashboard_link
    return link if client.cluster is not None or page_answers(link) else None


def page_answers(url: str) -> bool:
    """Does an HTTP GET of ``url`` succeed (2xx after redirects) within DASHBOARD_PROBE_SECONDS?"""
    import urllib.request
    try:
        with urllib.request.urlopen(url, timeout=DASHBOARD_PROBE_SECONDS) as response:   # noqa: S310 -- http only
            return 200 <= response.status < 300
    except (OSError, ValueError):     # refused, timed out, 404 (HTTPError), not a URL
        return False
