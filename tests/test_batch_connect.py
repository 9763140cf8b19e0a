"""clrt batch render when the scheduler is not one, and on a real Ctrl-C (found by
an audit of the batch's failure handling).  Small: tiny images, one local
worker, servers on loopback ports; every process started is stopped."""

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from clrt.scene import primitives  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _obj(path):
    mesh = primitives.icosphere(1)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


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
    # Dask reads the reply as a frame length (MemoryError): not an OpenCL error.  In
    # a process of its own: the failed Client leaves Dask's state behind, which a
    # later local cluster of the test process would wait on.
    server = _Server("reply")
    try:
        proc = subprocess.run([sys.executable, "-m", "clrt", "batch", "render", str(_obj(tmp_path / "m.obj")),
                               "-o", str(tmp_path / "out"), "--scheduler", server.address, "-q"],
                              env=_env(), capture_output=True, text=True, timeout=60)
    finally:
        server.close()
    assert proc.returncode == 2, proc.stderr[-500:]
    assert "OpenCL" not in proc.stderr and "cannot reach the Dask scheduler" in proc.stderr, proc.stderr[-500:]
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr[-500:]
    assert not (tmp_path / "out").exists()


def test_scheduler_address_of_a_silent_server_fails_within_the_connect_timeout():
    # Client(timeout=...) does not bound Dask's handshake read: connect's own deadline does
    server = _Server("silent")
    code = ("import clrt.batch.cluster as c\n"
            "c.BATCH_CONNECT_TIMEOUT = 1.0\n"
            f"c.connect({server.address!r})\n")
    try:
        proc = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True, text=True,
                              timeout=12)
    except subprocess.TimeoutExpired:
        pytest.fail("connect() to a silent server still waiting after 12 s (timeout 1 s)")
    finally:
        server.close()
    assert proc.returncode != 0 and "cannot reach the Dask scheduler" in proc.stderr, proc.stderr[-500:]


def test_real_ctrl_c_of_the_command_is_handled_by_the_batch(tmp_path):
    # the batch's own handler runs (final manifest, cluster closed, how to resume),
    # not clrt/__init__.py's start-up one (exit at once)
    mesh = _obj(tmp_path / "m.obj")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "clrt", "batch", "render", str(mesh), "-o", str(out),
                             "--views", "400", "--width", "32", "--height", "24", "--samples", "4",
                             "--workers", "1", "-q"], env=_env(), stderr=subprocess.PIPE, text=True)
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
