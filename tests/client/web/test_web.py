"""`objdb web` in a real browser (headless Chromium through chromedriver) against a server that
holds a short lounge database, and its HTTP answers to bad input.

Every page must load without a JavaScript error or a failed request, and the 3D pages must draw
(the WebGL canvas is sampled). Screenshots go to OBJDB_ARTIFACTS (default build/test-artifacts/web).
"""

import json
import ssl
import os
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from selenium import webdriver
from selenium.webdriver.chrome.service import Service

from conftest import BIN, ROOT, Process, Server

ARTIFACTS = Path(os.environ.get("OBJDB_ARTIFACTS", ROOT / "build" / "test-artifacts" / "web"))


def start_web(folder: Path, server_address: str, *args, listen="127.0.0.1:0") -> Process:
    folder.mkdir(parents=True, exist_ok=True)
    web = Process([BIN / "objdb", "web", "--server", server_address, "--listen", listen, *args],
                  folder / "web.log", r"serving on (https?)://[^:]+:(\d+)")
    web.url = f"{web.match.group(1)}://127.0.0.1:{web.match.group(2)}"
    web.server_address = server_address
    return web


@pytest.fixture(scope="module")
def lounge(tmp_path_factory):
    """A server holding the lounge's three sessions, 40 frames each, and `objdb web` on it with
    the sessions' datasets (for the merge-sheet rows)."""
    root = tmp_path_factory.mktemp("lounge")
    data = root / "lounge"
    subprocess.run([BIN / "objdb", "sim", "--preset", "lounge", "--frames", "40", "--out", data],
                   check=True, capture_output=True)
    server = Server(root / "server")
    subprocess.run([BIN / "objdb", "stream", "--server", server.address, data], check=True,
                   capture_output=True)
    datasets = [a for s in sorted(data.glob("session_*")) for a in ("--dataset", f"{s.name}={s}")]
    web = start_web(root / "web", server.address, *datasets)
    yield web
    web.stop()
    server.stop()


@pytest.fixture(scope="module")
def browser():
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                 "--window-size=1280,900", "--use-gl=angle", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    driver.set_page_load_timeout(120)
    yield driver
    driver.quit()


def load(browser, url: str, name: str, seconds: float = 120) -> float:
    """Opens `url`, waits until the page says it is ready (or shows an error), saves a
    screenshot and fails on any error the page or the browser reported. Returns the seconds."""
    start = time.monotonic()
    browser.get(url)
    state = None
    while time.monotonic() - start < seconds:
        state = browser.execute_script(
            "return {ready: document.body && document.body.dataset.ready === '1',"
            " errors: window.objdbErrors || []};")
        if state["ready"] or state["errors"]:
            break
        time.sleep(0.1)
    elapsed = time.monotonic() - start
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(ARTIFACTS / f"{name}.png"))
    logs = browser.get_log("browser")
    severe = [entry["message"] for entry in logs if entry["level"] == "SEVERE"]
    assert not state["errors"], f"{url}: the page reported {state['errors']}"
    assert not severe, f"{url}: the browser reported {severe}"
    assert state["ready"], f"{url}: not ready after {seconds} s"
    return elapsed


DRAWN = """
const canvas = document.querySelector('canvas');
if (!canvas) return -1;
const copy = document.createElement('canvas');
copy.width = canvas.width; copy.height = canvas.height;
const g = copy.getContext('2d');
g.drawImage(canvas, 0, 0);
const d = g.getImageData(0, 0, copy.width, copy.height).data;
let drawn = 0;
for (let i = 0; i < d.length; i += 4) if (d[i] < 240 || d[i + 1] < 240 || d[i + 2] < 240) ++drawn;
return drawn / (d.length / 4);
"""


def get_json(url: str):
    try:
        with urllib.request.urlopen(url, timeout=60) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def test_every_page_loads_and_draws(lounge, browser):
    sessions = load(browser, f"{lounge.url}/", "sessions")
    rows = browser.find_elements("css selector", "#sessions tbody tr")
    assert len(rows) == 3
    print(f"sessions page: {sessions:.2f} s")

    gallery = load(browser, f"{lounge.url}/objects.html", "objects")
    _, listed = get_json(f"{lounge.url}/api/objects?page_size=1000")
    objects = [o for o in listed["objects"] if not o.get("planar")]
    count = len(objects)
    assert count > 5
    cards = browser.find_elements("css selector", ".card")
    assert len(cards) == count  # objects first: planar pieces only when asked
    planar_count = len(listed["objects"]) - count
    if planar_count:
        summary = browser.find_element("css selector", "#summary").text
        assert f"also show {planar_count} planar piece" in summary, summary
    load(browser, f"{lounge.url}/objects.html?planar=1", "objects-with-planar")
    assert len(browser.find_elements("css selector", ".card")) == len(listed["objects"])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and browser.execute_script(
            "return [...document.images].some(i => !i.complete);"):
        time.sleep(0.1)
    broken = browser.execute_script(
        "return [...document.images].filter(i => i.naturalWidth === 0).map(i => i.src);")
    assert not broken, f"thumbnails that did not load: {broken}"
    # The second time, the thumbnails come from objdb web's cache.
    cached = load(browser, f"{lounge.url}/objects.html", "objects-cached")
    print(f"gallery of {count} objects: {gallery:.2f} s, {cached:.2f} s with thumbnails cached")

    merged = [o for o in listed["objects"] if int(o["num_poses"]) > 1]
    assert merged, "the short lounge has at least one merged model"
    target = merged[0]["id"]
    seconds = load(browser, f"{lounge.url}/object.html?id={target}", "object")
    assert browser.execute_script(DRAWN) > 0.01, "the object's 3D view is blank"
    tree = browser.find_element("id", "tree").text
    assert "e_TSDF" in tree and "e_ICP" in tree and "o_TSDF" in tree
    # The merge-sheet row over the datasets' frames (objdb web --dataset).
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not browser.execute_script(
            "return document.getElementById('sheet-row').complete;"):
        time.sleep(0.1)
    assert browser.execute_script("return document.getElementById('sheet-row').naturalWidth;") \
        == 2220, "the merge-sheet row did not load"
    browser.execute_script("document.getElementById('sheet').scrollIntoView();")
    browser.save_screenshot(str(ARTIFACTS / "object-with-sheet.png"))
    rendered = browser.execute_script("return document.body.dataset.renderedMs;")
    print(f"object page: {seconds:.2f} s, first render {rendered} ms after navigation start")
    # "Find similar" (Match of the stored object): an answer, a table or the reason.
    browser.find_element("id", "find-similar").click()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not browser.execute_script(
            "return document.body.dataset.similar;"):
        time.sleep(0.1)
    assert browser.execute_script("return document.body.dataset.similar;") not in (None, "error")
    assert browser.find_element("id", "similar").text.strip()
    status, body = get_json(f"{lounge.url}/api/objects/{target}/similar?max_results=3")
    assert status == 200 and body["matchable"] and len(body.get("results", [])) <= 3
    for r in body.get("results", []):
        assert r["object_id"] != target and "evidence" in r

    session = merged[0]["session_names"][0]
    for completed in (0, 1):
        seconds = load(browser, f"{lounge.url}/scene.html?session={session}&completed={completed}",
                       f"scene-{'completed' if completed else 'raw'}")
        assert browser.execute_script(DRAWN) > 0.05, "the scene's 3D view is blank"
        assert "object" in browser.find_element("id", "legend").text
        print(f"scene page ({'completed' if completed else 'raw'}): {seconds:.2f} s")


def test_a_page_with_a_bad_id_shows_the_error(lounge, browser):
    browser.get(f"{lounge.url}/object.html?id=987654")
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not browser.execute_script(
            "return (window.objdbErrors || []).length"):
        time.sleep(0.1)
    banner = browser.find_element("id", "error")
    assert banner.is_displayed() and "no object 987654" in banner.text
    browser.get_log("browser")  # the 404 is expected here; clear it


def test_bad_requests_get_clear_http_errors(lounge, tmp_path):
    status, body = get_json(f"{lounge.url}/api/objects/987654")
    assert status == 404 and body["grpc_code"] == "NOT_FOUND" and "987654" in body["error"]
    status, body = get_json(f"{lounge.url}/api/objects/abc")
    assert status == 400 and "not an object id" in body["error"]
    status, body = get_json(f"{lounge.url}/api/objects?page_size=lots")
    assert status == 400 and "page_size" in body["error"]
    status, body = get_json(f"{lounge.url}/api/objects?structure=maybe")
    assert status == 400 and "structure" in body["error"]
    status, body = get_json(f"{lounge.url}/api/objects?colour=red")
    assert status == 400 and "unknown query parameter 'colour'" in body["error"]
    status, body = get_json(f"{lounge.url}/api/sessions/nobody/scene.ply")
    assert status == 404 and "nobody" in body["error"]
    status, body = get_json(f"{lounge.url}/api/nothing")
    assert status == 404
    status, body = get_json(f"{lounge.url}/api/objects/987654/sheet.png")
    assert status == 404
    status, body = get_json(f"{lounge.url}/api/objects/987654/similar")
    assert status == 404 and "object_id" in body["error"]
    status, body = get_json(f"{lounge.url}/api/objects/1/similar?max_results=many")
    assert status == 400 and "max_results" in body["error"]
    request = urllib.request.Request(f"{lounge.url}/api/stats", method="POST", data=b"x")
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(request, timeout=30)
    assert e.value.code >= 400  # read-only: nothing but GET is served

    # An objdb server that is down: 503 with the gRPC message.
    down = start_web(tmp_path / "down", "127.0.0.1:1", "--timeout", "5")
    try:
        status, body = get_json(f"{down.url}/api/sessions")
        assert status == 503 and body["grpc_code"] == "UNAVAILABLE" and body["error"]
    finally:
        down.stop()


def test_only_loopback_without_https_and_a_token(tmp_path):
    refused = subprocess.run([BIN / "objdb", "web", "--listen", "0.0.0.0:0"], capture_output=True,
                             text=True, timeout=60)
    assert refused.returncode == 1 and "refusing to serve on 0.0.0.0:0" in refused.stderr
    missing = subprocess.run([BIN / "objdb", "web", "--pages", tmp_path], capture_output=True,
                             text=True, timeout=60)
    assert missing.returncode == 1 and "index.html missing" in missing.stderr
    no_folder = subprocess.run([BIN / "objdb", "web", "--dataset", f"s={tmp_path / 'none'}"],
                               capture_output=True, text=True, timeout=60)
    assert no_folder.returncode == 1 and "no such folder" in no_folder.stderr
    malformed = subprocess.run([BIN / "objdb", "web", "--dataset", "nothing"],
                               capture_output=True, text=True, timeout=60)
    assert malformed.returncode == 2 and "SESSION=DIR" in malformed.stderr


def test_a_web_token_guards_every_page(lounge, tmp_path):
    token = "web-viewer-test-token-0123456789"
    (tmp_path / "token").write_text(token)
    web = start_web(tmp_path / "guarded", lounge.server_address, "--web-token-file", tmp_path / "token")
    try:
        status, body = get_json(f"{web.url}/api/stats")
        assert status == 401 and token not in body["error"]
        request = urllib.request.Request(f"{web.url}/api/stats",
                                         headers={"Authorization": f"Bearer {token}"})
        with urllib.request.urlopen(request, timeout=30) as response:
            assert response.status == 200
        status, _ = get_json(f"{web.url}/login?token=wrong")
        assert status == 401

        class NoRedirect(urllib.request.HTTPRedirectHandler):
            def redirect_request(self, *args):
                return None

        opener = urllib.request.build_opener(NoRedirect)
        with pytest.raises(urllib.error.HTTPError) as e:
            opener.open(f"{web.url}/login?token={token}", timeout=30)
        assert e.value.code == 303
        cookie = e.value.headers["Set-Cookie"].split(";")[0]
        assert "HttpOnly" in e.value.headers["Set-Cookie"]
        request = urllib.request.Request(f"{web.url}/index.html", headers={"Cookie": cookie})
        with urllib.request.urlopen(request, timeout=30) as response:
            assert response.status == 200
    finally:
        web.stop()


def test_https_and_a_token_serve_a_remote_address(lounge, tmp_path):
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key,
                    "-out", cert, "-days", "1", "-subj", "/CN=localhost",
                    "-addext", "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True)
    token = "https-web-viewer-token-0123456789"
    (tmp_path / "token").write_text(token)
    web = start_web(tmp_path / "https", lounge.server_address, "--https-cert", cert,
                    "--https-key", key, "--web-token-file", tmp_path / "token",
                    listen="0.0.0.0:0")
    try:
        assert web.url.startswith("https://")
        context = ssl.create_default_context(cafile=str(cert))
        request = urllib.request.Request(f"{web.url}/api/sessions",
                                         headers={"Authorization": f"Bearer {token}"})
        with urllib.request.urlopen(request, timeout=30, context=context) as response:
            assert len(json.loads(response.read())["sessions"]) == 3
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(f"{web.url}/api/sessions", timeout=30, context=context)
        assert e.value.code == 401
    finally:
        web.stop()
    # HTTPS without a token is still refused on a remote address.
    refused = subprocess.run([BIN / "objdb", "web", "--listen", "0.0.0.0:0", "--https-cert", cert,
                              "--https-key", key], capture_output=True, text=True, timeout=60)
    assert refused.returncode == 1 and "refusing to serve" in refused.stderr
    half = subprocess.run([BIN / "objdb", "web", "--https-cert", cert], capture_output=True,
                          text=True, timeout=60)
    assert half.returncode == 1 and "both --https-cert and --https-key" in half.stderr
