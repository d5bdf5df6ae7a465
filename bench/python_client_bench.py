#!/usr/bin/python3
"""The Python client against the C++ client, in one run on one server.

Streams the same dataset as one session with `objdb stream --no-end` (C++: decodes the PNGs,
sends FLOAT32 depth and RGB8 colour) and with objdb.Client.stream(end=False) (sends the PNG
files as they are), alternating which goes first, and prints frames/s of each and the ratio.
Then ends the sessions and times Client.object(id) (mesh and cloud) of the object with the most
surface points.

usage: PYTHONPATH=build/python /usr/bin/python3 bench/python_client_bench.py [DATASET] [--repeats N]
(default data/lounge/session_1; build first: scripts/build.sh)
"""

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import objdb

ROOT = Path(__file__).resolve().parents[1]
BIN = ROOT / "build" / "bin"


def start_server(folder: Path):
    log = open(folder / "server.log", "w")
    process = subprocess.Popen([str(BIN / "objdb-server"), "--listen", "127.0.0.1:0", "--db",
                                str(folder / "bench.sqlite")], stdout=log, stderr=subprocess.STDOUT)
    for _ in range(600):
        match = re.search(r"listening on (127\.0\.0\.1:\d+)", (folder / "server.log").read_text())
        if match:
            return process, match.group(1)
        time.sleep(0.1)
    process.kill()
    sys.exit("objdb-server did not start")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("dataset", nargs="?", default=str(ROOT / "data/lounge/session_1"))
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    dataset = Path(args.dataset)
    frames = len(objdb.Dataset(dataset))
    with tempfile.TemporaryDirectory(prefix="objdb-pybench.") as tmp:
        process, address = start_server(Path(tmp))
        rates = {"C++": [], "Python": []}
        names = []
        try:
            db = objdb.Client(address)
            for r in range(args.repeats):
                order = ["C++", "Python"] if r % 2 == 0 else ["Python", "C++"]
                for who in order:
                    name = f"{who.lower().replace('+', 'p')}-{r}"
                    names.append(name)
                    start = time.monotonic()
                    if who == "C++":
                        # The dataset folder's name is the session's; give each run its own.
                        link = Path(tmp) / name
                        link.symlink_to(dataset.resolve())
                        subprocess.run([str(BIN / "objdb"), "stream", "--server", address,
                                        "--no-end", str(link)], check=True,
                                       capture_output=True)
                    else:
                        acks = sum(isinstance(e, objdb.FrameAck)
                                   for e in db.stream(dataset, session=name, end=False))
                        assert acks == frames, (acks, frames)
                    rates[who].append(frames / (time.monotonic() - start))
                    print(f"{who:7s} run {r + 1}: {rates[who][-1]:6.1f} frames/s", flush=True)
            cpp, py = statistics.mean(rates["C++"]), statistics.mean(rates["Python"])
            print(f"\n{dataset} ({frames} frames), {args.repeats} runs each")
            print(f"{'client':8s} {'frames/s':>9s}")
            print(f"{'C++':8s} {cpp:9.1f}\n{'Python':8s} {py:9.1f}")
            print(f"Python / C++: {py / cpp:.2f}")

            for name in names:
                db.end_session(name)
            objects = db.objects()
            largest = max(objects, key=lambda o: db.object(o.id, mesh=False, cloud=False)
                          .stats.get("num_points", 0))
            detail = db.object(largest.id)
            times = []
            for _ in range(20):
                start = time.perf_counter()
                db.object(largest.id)
                times.append(1000 * (time.perf_counter() - start))
            print(f"\nobject({largest.id}): {len(detail.cloud.points)} cloud points, "
                  f"{len(detail.mesh.vertices)} mesh vertices, {len(detail.poses)} poses: "
                  f"median {statistics.median(times):.1f} ms, max {max(times):.1f} ms over 20 calls")
        finally:
            process.terminate()
            process.wait()


if __name__ == "__main__":
    main()
