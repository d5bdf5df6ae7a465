#!/usr/bin/python3
"""`objdb web` on the lounge in headless Chromium: the gallery's load time with thumbnails drawn
(first visit) and cached (second), and the object page's first render.

Streams the lounge (data/lounge; generated when missing) into a fresh server, starts `objdb web`
on it, and loads the pages through chromedriver (SwiftShader WebGL, as the tests do).

usage: /usr/bin/python3 bench/web_bench.py [DATASET] [--repeats N]   (build first: scripts/build.sh)
"""

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from selenium import webdriver
from selenium.webdriver.chrome.service import Service

ROOT = Path(__file__).resolve().parents[1]
BIN = ROOT / "build" / "bin"


def start(args, log: Path, pattern: str):
    out = open(log, "w")
    process = subprocess.Popen([str(a) for a in args], stdout=out, stderr=subprocess.STDOUT)
    for _ in range(600):
        match = re.search(pattern, log.read_text())
        if match:
            return process, match.group(1)
        if process.poll() is not None:
            break
        time.sleep(0.1)
    sys.exit(f"{args[0]} did not start:\n{log.read_text()}")


def wait_ready(driver, seconds=300):
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        if driver.execute_script("return document.body && document.body.dataset.ready === '1'"):
            return
        errors = driver.execute_script("return window.objdbErrors || []")
        if errors:
            sys.exit(f"the page failed: {errors}")
        time.sleep(0.02)
    sys.exit("the page did not get ready")


def gallery(driver, url) -> float:
    start = time.monotonic()
    driver.get(f"{url}/objects.html")
    wait_ready(driver)
    while driver.execute_script("return [...document.images].some(i => !i.complete)"):
        time.sleep(0.02)
    return time.monotonic() - start


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("dataset", nargs="?", default=str(ROOT / "data/lounge"))
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    dataset = Path(args.dataset)
    if not dataset.exists():
        subprocess.run([BIN / "objdb", "sim", "--preset", "lounge", "--out", dataset], check=True,
                       capture_output=True)
    with tempfile.TemporaryDirectory(prefix="objdb-webbench.") as tmp:
        tmp = Path(tmp)
        server, address = start([BIN / "objdb-server", "--listen", "127.0.0.1:0", "--db",
                                 tmp / "db.sqlite"], tmp / "server.log",
                                r"listening on (127\.0\.0\.1:\d+)")
        web = None
        options = webdriver.ChromeOptions()
        options.binary_location = "/usr/bin/chromium"
        for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                     "--window-size=1280,900", "--use-gl=angle", "--use-angle=swiftshader",
                     "--enable-unsafe-swiftshader"):
            options.add_argument(flag)
        driver = None
        try:
            print(f"streaming {dataset} ...", flush=True)
            subprocess.run([BIN / "objdb", "stream", "--server", address, dataset], check=True,
                           capture_output=True)
            web, url = start([BIN / "objdb", "web", "--server", address, "--listen",
                              "127.0.0.1:0"], tmp / "web.log", r"serving on (http://\S+)")
            with urllib.request.urlopen(f"{url}/api/objects?page_size=1000") as r:
                objects = json.loads(r.read())["objects"]
            driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
            first = gallery(driver, url)
            cached = [gallery(driver, url) for _ in range(args.repeats)]
            largest = max(objects, key=lambda o: int(o["num_poses"]))["id"]
            renders = []
            for _ in range(args.repeats):
                driver.get(f"{url}/object.html?id={largest}")
                wait_ready(driver)
                renders.append(int(driver.execute_script("return document.body.dataset.renderedMs")))
            print(f"\n{dataset}: {len(objects)} objects in the gallery (two thumbnails each)")
            print(f"{'what':48s} {'seconds':>8s}")
            print(f"{'gallery, thumbnails drawn (first visit)':48s} {first:8.2f}")
            print(f"{'gallery, thumbnails cached (median)':48s} {statistics.median(cached):8.2f}")
            print(f"{f'object {largest} page, first render (median)':48s} "
                  f"{statistics.median(renders) / 1000:8.2f}")
        finally:
            if driver is not None:
                driver.quit()
            for p in (web, server):
                if p is not None:
                    p.terminate()
                    p.wait()


if __name__ == "__main__":
    main()
