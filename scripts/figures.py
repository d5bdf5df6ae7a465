#!/usr/bin/env python3
"""Measures the figures docs/results.md reports and writes that page: `objdb eval` (the server's
protocol, in process) on the synthetic lounge and kitchen, and on every real sequence of
../shared/data that is present, the sensor-rate benchmark on a real VGA sequence, and the
README's first command (scripts/demo.sh, with the build done; it writes data/). The page
says the date, the commit and the machine; the README and the docs link to it instead of keeping
copies of measured figures (scripts/check_docs.py fails on a copy that differs).

    scripts/figures.py [--short] [--out FILE] [--build DIR] [--data DIR]

--short: the lounge with 40 frames per session only (a check that the script works end to end,
about a minute; CTest FiguresScriptWritesTheResultsTable). Default --out docs/results.md, --build
build, --data ../shared/data. Exit status 1 when a command fails or prints no figure.
"""

import argparse
import datetime
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# The real sequences, as objdb eval takes them (one eval per entry: several folders are the
# sessions of one database).
REAL = [
    ("SUN3D study room (2 sessions, real, VGA)",
     ["sun3d-studyroom/fragment-1", "sun3d-studyroom/fragment-2"]),
    ("ICL-NUIM living room (rendered, room scale)", ["icl-livingroom1-micro"]),
    ("desk box (RealSense)", ["desk-box-realsense"]),
    ("shelf bin with class labels (RealSense)", ["shelf-bin-labels-realsense"]),
]

# objdb eval's lines (client/db_score.cpp, client/eval_command.cpp) and the column each fills.
PATTERNS = {
    "placements": r"^placements \(raw segments in the database\)\s+(\d+)",
    "giant": r"giant objects \(not structure, > 2\.5 m\)\s+(\d+)",
    "structure_planar": r"^  structure / planar \(the database's flags\)\s+(\d+ / \d+)",
    "chair_sized": r"chair-sized \(0\.6-1\.3 m, smallest span >= 0\.3 m\)\s+(\d+)",
    "largest": r"^largest object \(not structure\)\s+([\d.]+) m",
    "places2": r"^objects at >= 2 places\s+(\d+)",
    "erroneous": r"^erroneous merges \(kinds differ\)\s+(\d+)",
    "structure_merges": r"^structure merges \(true structure in a model of >= 2\)\s+(\d+)",
    "recall": r"^repeated kinds' mergeable segments with their kind elsewhere\s+(\d+ % \(\d+ of \d+\))",
    "placement_purity": r"^purity of object placements \(mean; under 80 %\)\s+(\d+ %)",
    "model_purity": r"^purity of object models \(mean, least; under 95 %\)\s+(\d+ %, \d+ %)",
    "seconds": r"^all sessions: ([\d.]+) s",
}


def run(command, log: Path) -> str:
    """Runs `command`, keeps its output in `log`, returns stdout; raises on failure."""
    started = time.monotonic()
    result = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    log.write_text(result.stdout + result.stderr)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, command))} exited {result.returncode} "
                           f"(output in {log})")
    print(f"  {' '.join(map(str, command))}: {time.monotonic() - started:.0f} s", flush=True)
    return result.stdout


def figures(output: str) -> dict:
    found = {}
    for key, pattern in PATTERNS.items():
        m = re.search(pattern, output, re.MULTILINE)
        if m:
            found[key] = m.group(1)
    if "placements" not in found:
        raise RuntimeError("objdb eval printed no census")
    return found


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    memory = ""
    try:
        kib = int(Path("/proc/meminfo").read_text().split()[1])
        memory = f", {kib / 1024 / 1024:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return f"{os.cpu_count()} cores ({cpu}){memory}, {platform.system()} {platform.release()}"


def commit() -> str:
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=ROOT, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, cwd=ROOT).stdout.strip()
        return head + (" with uncommitted changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"


def main(argv) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--short", action="store_true")
    parser.add_argument("--out", default=str(ROOT / "docs" / "results.md"))
    parser.add_argument("--build", default=str(ROOT / "build"))
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    args = parser.parse_args(argv)
    objdb = Path(args.build) / "bin" / "objdb"
    frame_bench = Path(args.build) / "bin" / "frame_bench"
    data = Path(args.data)
    if not objdb.is_file():
        print(f"figures: no {objdb}: build first (README's test command)", file=sys.stderr)
        return 1

    rows, notes = [], []
    with tempfile.TemporaryDirectory(prefix="objdb-figures-") as tmp:
        tmp = Path(tmp)
        evals = []  # (name, datasets, the command that made them)
        sim = [("synthetic lounge (3 sessions, Tango)", "lounge")]
        if not args.short:
            sim.append(("synthetic kitchen (2 sessions, Kinect-like)", "kitchen"))
        for name, preset in sim:
            out = tmp / preset
            command = [objdb, "sim", "--preset", preset, "--out", out]
            if args.short:
                command += ["--frames", "40"]
                name = name.replace("3 sessions", "3 sessions of 40 frames")
            run(command, tmp / f"sim-{preset}.log")
            made = " ".join(str(c) for c in command[1:]).replace(str(tmp) + "/", "")
            evals.append((name, [out], f"objdb {made}; "))
        if not args.short:
            for name, folders in REAL:
                paths = [data / f for f in folders]
                if all(p.is_dir() for p in paths):
                    evals.append((name, paths, ""))
                else:
                    notes.append(f"{name}: not measured ({paths[0]} absent)")
        for i, (name, paths, made) in enumerate(evals):
            output = run([objdb, "eval", *paths, "--db", tmp / f"eval-{i}.sqlite"],
                         tmp / f"eval-{i}.log")
            f = figures(output)
            f["name"] = name
            f["command"] = made + "objdb eval " + " ".join(
                str(p).replace(str(data), "../shared/data").replace(str(tmp) + "/", "")
                for p in paths)
            rows.append(f)
        demo = None
        if not args.short:
            started = time.monotonic()
            output = run(["bash", "scripts/demo.sh"], tmp / "demo.log")
            seconds = time.monotonic() - started
            models = re.search(r"objects: (\d+) active", output)
            demo = (f"{seconds:.0f}", models.group(1) if models else "?")
        rate = None
        sun3d = data / "sun3d-studyroom" / "fragment-1"
        if not args.short and sun3d.is_dir() and frame_bench.is_file():
            output = run([frame_bench, "--dataset", sun3d, "--server-frames", "1000"],
                         tmp / "frame_bench.log")
            m = re.search(r"acknowledged frames/s\s+([\d.]+)", output)
            segments = re.search(r"segments into the database\s+(\d+)", output)
            end = re.search(r"EndSession \(flush \+ final inserts\), s\s+([\d.]+)", output)
            rss = re.search(r"peak RSS \(bench \+ server\), MB\s+(\d+)", output)
            if not m:
                raise RuntimeError("frame_bench printed no acknowledged frames/s")
            rate = (m.group(1), segments.group(1) if segments else "?",
                    end.group(1) if end else "?", rss.group(1) if rss else "?")

    def cell(row, key):
        return row.get(key, "–")

    lines = [
        "# Results",
        "",
        "Generated by `scripts/figures.py`" + (" --short" if args.short else "") +
        "; do not edit by hand. The README and the docs link here instead of keeping copies of "
        "measured figures.",
        "",
        f"- date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC",
        f"- commit: {commit()}",
        f"- machine: {machine()}",
        "",
        "## Objects, on the server's protocol (`objdb eval`)",
        "",
        "Giant: an object (not structure) larger than 2.5 m. Chair-sized: 0.6–1.3 m with its "
        "smallest span at least 0.3 m. Structure / planar: placements the database flags as "
        "room structure (floor, walls, faces) and as planar pieces; neither is ever matched. "
        "Merges, recall and purity need ground truth (the "
        "synthetic scenes); `–` where a sequence has none. Recall: the share of repeated kinds' "
        "mergeable segments that share a model with their kind at another place. Purity: the "
        "share of a placement's (a model's) points on its own true object (kind).",
        "",
        "| dataset | placements | structure / planar | giant | largest (m) | chair-sized | "
        "objects at ≥ 2 places | "
        "erroneous / structure merges | recall | placement purity | model purity (mean, least) "
        "| time (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        merges = (f"{r['erroneous']} / {r['structure_merges']}"
                  if "erroneous" in r and "structure_merges" in r else "–")
        lines.append(
            f"| {r['name']} | {cell(r, 'placements')} | {cell(r, 'structure_planar')} | "
            f"{cell(r, 'giant')} | "
            f"{cell(r, 'largest')} | {cell(r, 'chair_sized')} | {cell(r, 'places2')} | {merges} | "
            f"{cell(r, 'recall')} | {cell(r, 'placement_purity')} | {cell(r, 'model_purity')} | "
            f"{cell(r, 'seconds')} |")
    lines += ["", "Commands (from the repository root, `build/bin/` on the PATH):", ""]
    lines += [f"- {r['name']}: `{r['command']}`" for r in rows]
    if rate:
        lines += [
            "",
            "## Sensor rate",
            "",
            "| figure | value |",
            "|---|---|",
            f"| acknowledged frames/s, 1,000 real VGA frames on one Ingest stream (SUN3D fragment 1 "
            f"forward and back) | {rate[0]} |",
            f"| segments into the database | {rate[1]} |",
            f"| EndSession, s | {rate[2]} |",
            f"| peak RSS (bench + server), MB | {rate[3]} |",
            "",
            "Command: `build/bin/frame_bench --dataset ../shared/data/sun3d-studyroom/fragment-1 "
            "--server-frames 1000`",
        ]
    if demo:
        lines += [
            "",
            "## The README's first command",
            "",
            f"`bash scripts/demo.sh` with the build done (the lounge generated, its three sessions "
            f"streamed to objdb-server, queries, the completed scene, the file checked): "
            f"{demo[0]} s, {demo[1]} active objects in the database.",
        ]
    if notes:
        lines += ["", "Not measured:", ""] + [f"- {n}" for n in notes]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"figures: {len(rows)} datasets written to {args.out}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except RuntimeError as e:
        print(f"figures: {e}", file=sys.stderr)
        sys.exit(1)
