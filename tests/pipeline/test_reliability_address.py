"""Reliability, second pass: ``cluster.address`` pointing at something that is not a Dask
scheduler is refused at once (exit 2, one line naming what answered), before any store is written.

The servers are started here, on free loopback ports, in daemon threads; every wait is bounded.
"""

from __future__ import annotations

import http.server
import re
import socket
import threading

import pytest
from helpers import TINY_RUN, cli, finish

from vasc_pipeline import config
from vasc_pipeline.config import ConfigError
from vasc_pipeline.pipeline import orchestrate


@pytest.fixture
def http_port():
    """A tiny HTTP server (as a dashboard's port would be) on a free loopback port."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    thread.start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()
        thread.join(10)


def _serve(sock: socket.socket, banner: bytes | None, stop: threading.Event) -> None:
    sock.settimeout(0.1)
    held = []
    while not stop.is_set():
        try:
            conn, _ = sock.accept()
        except TimeoutError:
            continue
        except OSError:
            return
        if banner is not None:
            conn.sendall(banner)
        held.append(conn)  # kept open, never read: a service waiting for its own protocol
    for conn in held:
        conn.close()


@pytest.fixture
def tcp_server():
    """Start a raw TCP server on a free loopback port that sends ``banner`` (None: stays silent)."""
    servers = []

    def start(banner: bytes | None) -> int:
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        stop = threading.Event()
        thread = threading.Thread(target=_serve, args=(sock, banner, stop), daemon=True)
        thread.start()
        servers.append((sock, stop, thread))
        return sock.getsockname()[1]

    yield start
    for sock, stop, thread in servers:
        stop.set()
        thread.join(10)
        sock.close()


def assert_refused_before_any_store(tmp_path, port: int, pattern: str) -> None:
    code, output = finish(
        cli(
            *TINY_RUN,
            f"output_dir={tmp_path}",
            "cluster=address",
            f"cluster.address=tcp://127.0.0.1:{port}",
            "cluster.startup_timeout=3",
        )
    )
    assert code == 2, output
    errors = [line for line in output.splitlines() if line.startswith("vasc_pipeline: error:")]
    assert len(errors) == 1 and "Traceback" not in output, output
    assert f"cluster.address tcp://127.0.0.1:{port}" in errors[0] and "expected a Dask scheduler" in errors[0]
    assert re.search(pattern, errors[0]), errors[0]
    assert not list(tmp_path.glob("runs/*.zarr")), output


def test_address_of_an_http_server_is_refused_naming_it(tmp_path, http_port):
    assert_refused_before_any_store(tmp_path, http_port, r"an HTTP server answered \('HTTP/1\.0 200 OK'")


def test_address_of_a_server_that_speaks_first_is_refused_naming_its_greeting(tmp_path, tcp_server):
    port = tcp_server(b"SSH-2.0-OpenSSH_9.6p1 Ubuntu-3ubuntu13\r\n")
    assert_refused_before_any_store(tmp_path, port, r"answered 'SSH-2\.0-OpenSSH_9\.6p1")


def test_address_of_a_silent_server_is_refused_after_the_startup_timeout(tmp_path, tcp_server):
    port = tcp_server(None)
    cfg = config.compose(
        [
            *TINY_RUN,
            f"output_dir={tmp_path}",
            "cluster=address",
            f"cluster.address=tcp://127.0.0.1:{port}",
            "cluster.startup_timeout=1",
        ]
    )
    with pytest.raises(ConfigError, match=r"sent no Dask greeting within 1 s"):
        orchestrate.run_sweep(cfg)
    assert not (tmp_path / "runs").exists()


def test_address_where_nothing_listens_is_refused(tmp_path):
    with socket.socket() as s:  # a port that was free a moment ago, closed again: nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = config.compose(
        [*TINY_RUN, f"output_dir={tmp_path}", "cluster=address", f"cluster.address=tcp://127.0.0.1:{port}"]
    )
    with pytest.raises(ConfigError, match=r"cannot connect \(Connection refused"):
        orchestrate.run_sweep(cfg)
    assert not (tmp_path / "runs").exists()
