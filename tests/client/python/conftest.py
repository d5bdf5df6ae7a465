"""Fixtures: real objdb-server processes on loopback and datasets written by `objdb sim`.

OBJDB_BIN names the folder of the built binaries (CTest sets it; default build/bin).
"""

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
BIN = Path(os.environ.get("OBJDB_BIN", ROOT / "build" / "bin"))


class Server:
    """An objdb-server on 127.0.0.1 with a port of its own, on a fresh SQLite database."""

    def __init__(self, folder: Path, *args):
        folder.mkdir(parents=True, exist_ok=True)
        self.log_path = folder / "server.log"
        self.log = open(self.log_path, "w")
        self.process = subprocess.Popen(
            [str(BIN / "objdb-server"), "--listen", "127.0.0.1:0", "--db",
             str(folder / "objects.sqlite"), *args],
            stdout=self.log, stderr=subprocess.STDOUT)
        self.address = None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            match = re.search(r"listening on (127\.0\.0\.1:\d+)", self.log_path.read_text())
            if match:
                self.address = match.group(1)
                return
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"objdb-server did not start:\n{self.log_path.read_text()}")

    def stop(self):
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()


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
def token_server(tmp_path):
    token = "python-client-test-token-0123456789"
    path = tmp_path / "token"
    path.write_text(token + "\n")
    s = Server(tmp_path / "server", "--token-file", str(path))
    s.token = token
    yield s
    s.stop()
