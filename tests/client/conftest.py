"""Fixtures of the Python tests (python/: the Python client, web/: objdb web in a browser): real
objdb-server processes on loopback and datasets written by `objdb sim`.

OBJDB_BIN names the folder of the built binaries (CTest sets it; default build/bin).
"""

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("OBJDB_BIN", ROOT / "build" / "bin"))


class Process:
    """A binary started with its output in `log_path`, running once `pattern` shows in it."""

    def __init__(self, args, log_path: Path, pattern: str, seconds: float = 60):
        self.log_path = log_path
        self.log = open(log_path, "w")
        self.process = subprocess.Popen([str(a) for a in args], stdout=self.log,
                                        stderr=subprocess.STDOUT)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.match = re.search(pattern, log_path.read_text())
            if self.match:
                return
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"{args[0]} did not start:\n{log_path.read_text()}")

    def stop(self):
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()


class Server(Process):
    """An objdb-server on 127.0.0.1 with a port of its own, on a fresh SQLite database."""

    def __init__(self, folder: Path, *args):
        folder.mkdir(parents=True, exist_ok=True)
        super().__init__([BIN / "objdb-server", "--listen", "127.0.0.1:0", "--db",
                          folder / "objects.sqlite", *args],
                         folder / "server.log", r"listening on (127\.0\.0\.1:\d+)")
        self.address = self.match.group(1)


@pytest.fixture(scope="session")
def two_boxes(tmp_path_factory) -> Path:
    """Two boxes on a floor, 30 frames in objdb's layout (`objdb sim --preset two-boxes`)."""
    out = tmp_path_factory.mktemp("data") / "two-boxes"
    subprocess.run([str(BIN / "objdb"), "sim", "--preset", "two-boxes", "--out", str(out)],
                   check=True, capture_output=True)
    return out


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path / "server")
    yield s
    s.stop()


@pytest.fixture
def keepalive_server(tmp_path):
    """A server that pings its clients after 0.5 s of silence and gives up 0.5 s later."""
    s = Server(tmp_path / "server", "--keepalive-s", "0.5", "--keepalive-timeout-s", "0.5")
    yield s
    s.stop()


@pytest.fixture
def token_server(tmp_path):
    token = "python-client-test-token-0123456789"
    path = tmp_path / "token"
    path.write_text(token + "\n")
    s = Server(tmp_path / "server", "--token-file", str(path))
    s.token = token
    yield s
    s.stop()
