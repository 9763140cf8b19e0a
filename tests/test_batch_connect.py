"""clrt batch render when the scheduler is not one, and on a real Ctrl-C (found by
an audit of the batch's failure handling).  Small: tiny images, one local
worker, servers on loopback ports; every process started is stopped."""

import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

pytest.importorskip("distributed")

from conftest import repo_env, write_icosphere_obj  # noqa: E402


def _python(code: str, seconds: float, waiting: str):
    """``python -c code`` with the clrt under test, its output captured; a test
    failure (``waiting``) rather than a hang past ``seconds``."""
    try:
        return subprocess.run([sys.executable, "-c", code], env=repo_env(), capture_output=True, text=True,
                              timeout=seconds)
    except subprocess.TimeoutExpired:
        pytest.fail(waiting)


class _Server:
    """A TCP server on a free loopback port that is not Dask: 'reply' answers
    anything with an HTTP error (as web servers and proxies do), 'silent'
    accepts and never answers (as servers that wait for a request line do)."""

    def __init__(self, mode):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.address = "tcp://127.0.0.1:%d" % self.sock.getsockname()[1]
        self.mode, self.conns = mode, []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            if self.mode == "reply":
                try:
                    conn.recv(65536)
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\nconnection: close\r\ncontent-length: 0\r\n\r\n")
                    conn.close()
                except OSError:
                    pass

    def close(self):
        self.sock.close()
        for c in self.conns:
            c.close()


def test_scheduler_address_of_a_server_that_answers_garbage_is_an_input_error(tmp_path):
    # Dask reads the reply as a frame length (MemoryError): not an OpenCL error.  The
    # command as a user runs it: its whole stderr is the one line.
    server = _Server("reply")
    try:
        mesh = write_icosphere_obj(tmp_path / "m.obj")
        proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", str(mesh),
                               "-o", str(tmp_path / "out"), "--scheduler", server.address, "-q"],
                              env=repo_env(), capture_output=True, text=True, timeout=60)
    finally:
        server.close()
    assert proc.returncode == 2, proc.stderr[-500:]
    assert "OpenCL" not in proc.stderr and "cannot reach the Dask scheduler" in proc.stderr, proc.stderr[-500:]
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr[-500:]
    assert not (tmp_path / "out").exists()


def test_a_refused_scheduler_port_fails_at_once(tmp_path, monkeypatch, capsys):
    """Dask's Client tries a refused port again until its timeout (10 s): clrt
    asks the port first.  With a timeout of a minute, the answer is still the
    refusal, not Dask's "timed out"."""
    from clrt.batch.cluster import connect
    from clrt.cli import main
    from clrt.errors import InputError
    monkeypatch.setattr("clrt.batch.cluster.BATCH_CONNECT_TIMEOUT", 60.0)
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()   # nothing listens there now
    with pytest.raises(InputError, match=f"connection refused \\(nothing listens on port {port} of 127.0.0.1\\)"):
        connect(f"tcp://127.0.0.1:{port}")
    mesh = write_icosphere_obj(tmp_path / "m.obj")
    assert main(["batch", "render", str(mesh), "-o", str(tmp_path / "out"), "--scheduler", f"127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err
    assert err == (f"clrt: cannot reach the Dask scheduler at tcp://127.0.0.1:{port}: connection refused "
                   f"(nothing listens on port {port} of 127.0.0.1)\n"), err
    assert not (tmp_path / "out").exists()


def test_scheduler_address_of_a_silent_server_fails_within_the_connect_timeout():
    # Client(timeout=...) does not bound Dask's handshake read: connect's own deadline does
    server = _Server("silent")
    code = ("import clrt.batch.cluster as c\n"
            "c.BATCH_CONNECT_TIMEOUT = 1.0\n"
            f"c.connect({server.address!r})\n")
    try:
        proc = _python(code, 12, "connect() to a silent server still waiting after 12 s (timeout 1 s)")
    finally:
        server.close()
    assert proc.returncode != 0 and "cannot reach the Dask scheduler" in proc.stderr, proc.stderr[-500:]


def test_a_failed_connect_leaves_nothing_a_later_batch_waits_on(tmp_path):
    """connect() to servers that are not Dask fails, and the process is as before:
    no Client left open or made the default, Dask's scheduler setting untouched --
    so a local cluster batch and a dask.compute after it finish (the compute used
    to wait for ever on the failed Client).  In a process of its own, with a
    deadline, and with the cyclic garbage collector off: it was what closed a
    failed Client, when it happened to run."""
    garbage, silent = _Server("reply"), _Server("silent")
    mesh = write_icosphere_obj(tmp_path / "m.obj")
    code = f"""
import gc
gc.disable()
import dask, dask.array as da, distributed
import clrt.batch, clrt.batch.cluster as c
from clrt.errors import InputError
c.BATCH_CONNECT_TIMEOUT = c.BATCH_HANDSHAKE_SLACK = 1.0
for address in ({garbage.address!r}, {silent.address!r}):
    try:
        c.connect(address)
    except InputError as exc:
        print(exc)
    left = [o for o in gc.get_objects() if isinstance(o, distributed.Client) and o.status != "closed"]
    assert not left, f"Clients left open: {{left}}"
    assert dask.config.get("scheduler", None) is None, dask.config.get("scheduler")
summary = clrt.batch.run([{str(mesh)!r}], {str(tmp_path / "out")!r}, views=1, workers=1,
                         width=20, height=14)
print(summary.rendered, int(da.arange(10, chunks=5).sum().compute()))
"""
    try:
        proc = _python(code, 90, "a batch after a failed connect still running after 90 s")
    finally:
        garbage.close()
        silent.close()
    assert proc.returncode == 0, proc.stderr[-1500:]
    lines = proc.stdout.splitlines()
    assert len(lines) == 3 and all("cannot reach the Dask scheduler" in line for line in lines[:2]), proc.stdout
    assert lines[2] == "1 45"


def test_real_ctrl_c_of_the_command_is_handled_by_the_batch(tmp_path):
    # the batch's own handler runs (final manifest, cluster closed, how to resume),
    # not clrt/__init__.py's start-up one (exit at once)
    mesh = write_icosphere_obj(tmp_path / "m.obj")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "clrt", "batch", "render", str(mesh), "-o", str(out),
                             "--views", "400", "--width", "32", "--height", "24", "--samples", "4",
                             "--workers", "1", "-q"], env=repo_env(), stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not list(out.glob("m/view-*.png")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before it could be interrupted"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130
    assert "run the same command again to resume" in err, err[-500:]


def test_a_dashboard_link_is_shown_only_if_its_page_answers():
    """A scheduler started with --no-dashboard still lists an HTTP service, whose
    /status page is missing: no link then; a page that answers keeps its link."""
    import http.server
    import threading

    from clrt.batch.cluster import dashboard_link

    class Pages(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200 if self.path == "/status" else 404)
            self.end_headers()
            self.wfile.write(b"ok")

        def log_message(self, *args):
            pass

    server = http.server.HTTPServer(("127.0.0.1", 0), Pages)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}"

    class RemoteClient:            # what dashboard_link reads of a distributed.Client
        cluster = None

        def __init__(self, link):
            self.dashboard_link = link

        def scheduler_info(self):
            return {"services": {"dashboard": server.server_address[1]}}

    try:
        assert dashboard_link(RemoteClient(base + "/status")) == base + "/status"
        assert dashboard_link(RemoteClient(base + "/missing")) is None
    finally:
        server.shutdown()
        server.server_close()
