"""The report page in a real browser: headless Chromium (Debian package ``chromium``) driven over the
DevTools protocol (a minimal WebSocket client on the standard library, no new dependency).

At 1280 and 1920 px wide the page must load without console errors (console calls, exceptions and
browser log entries of level error, which include Content-Security-Policy refusals and failed loads),
every image must decode with a non-zero natural size, nothing may be wider than the window, a
regime's rule must get at least 6 characters' width, the topology's key must be readable (≥ 12 px),
and the page must tell one story (the effect its summary names is in the effects table; an effect
reported missing comes with a located failure). A full-page screenshot per width is written as a
test artifact (its path is printed and recorded as the ``screenshot-<width>`` property in JUnit
XML; ``REPORT_SCREENSHOTS=<folder>`` keeps a copy there). A control page with one external image
and one inline script proves the error detection sees what it should.
"""

import base64
import io
import json
import os
import shutil
import socket
import subprocess
import time
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from PIL import Image
from test_report_page import report_page

CHROMIUM = shutil.which("chromium")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium is not installed (Debian: apt-get install -y chromium)")
WIDTHS = (1280, 1920)
HEIGHT = 900


class WebSocket:
    """Just enough of RFC 6455 for the DevTools protocol: text frames, client-side masking."""

    def __init__(self, url: str, timeout_s: float = 60.0):
        parts = urlsplit(url)
        self.socket = socket.create_connection((parts.hostname, parts.port), timeout=timeout_s)
        self.stream = self.socket.makefile("rb")
        key = base64.b64encode(os.urandom(16)).decode()
        self.socket.sendall((f"GET {parts.path} HTTP/1.1\r\nHost: {parts.netloc}\r\nUpgrade: websocket\r\n"
                             f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                             "Sec-WebSocket-Version: 13\r\n\r\n").encode())
        status = self.stream.readline()
        if b" 101 " not in status:
            raise ConnectionError(f"DevTools refused the WebSocket upgrade: {status!r}")
        while self.stream.readline() not in (b"\r\n", b""):
            pass

    def send(self, text: str) -> None:
        payload = text.encode("utf-8")
        n = len(payload)
        header = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + n.to_bytes(2, "big")
                                  if n < 1 << 16 else bytes([0x80 | 127]) + n.to_bytes(8, "big"))
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.socket.sendall(header + mask + masked)

    def _exact(self, n: int) -> bytes:
        data = self.stream.read(n)
        if len(data) != n:
            raise ConnectionError("DevTools closed the connection")
        return data

    def receive(self) -> str:
        message = b""
        while True:
            first, second = self._exact(2)
            n = second & 0x7F
            if n == 126:
                n = int.from_bytes(self._exact(2), "big")
            elif n == 127:
                n = int.from_bytes(self._exact(8), "big")
            mask = self._exact(4) if second & 0x80 else None
            data = self._exact(n)
            if mask:
                data = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
            opcode = first & 0x0F
            if opcode == 0x8:
                raise ConnectionError("DevTools closed the connection")
            if opcode in (0x9, 0xA):  # ping, pong: no message
                continue
            message += data
            if first & 0x80:
                return message.decode("utf-8")

    def close(self) -> None:
        self.stream.close()
        self.socket.close()


class DevToolsPage:
    """One browser tab: ``call`` a protocol method, with the events received meanwhile kept in ``events``."""

    def __init__(self, websocket_url: str):
        self.ws = WebSocket(websocket_url)
        self.events: list[dict] = []
        self._next_id = 0

    def call(self, method: str, **params) -> dict:
        self._next_id += 1
        self.ws.send(json.dumps({"id": self._next_id, "method": method, "params": params}))
        while True:
            message = json.loads(self.ws.receive())
            if message.get("id") == self._next_id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message["result"]
            self.events.append(message)

    def wait_for(self, event: str, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not any(e.get("method") == event for e in self.events):
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {event} within {timeout_s} s")
            self.events.append(json.loads(self.ws.receive()))

    def errors(self) -> list[str]:
        """Console errors, uncaught exceptions and browser log entries of level error."""
        found = []
        for e in self.events:
            method, params = e.get("method"), e.get("params", {})
            if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                found.append("console: " + " ".join(str(a.get("value", a.get("description"))) for a in params["args"]))
            elif method == "Runtime.exceptionThrown":
                found.append("exception: " + params["exceptionDetails"].get("text", ""))
            elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
                found.append(f"log ({params['entry']['source']}): {params['entry']['text']}")
        return found


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """Headless Chromium with the DevTools protocol on a free loopback port; yields its HTTP base URL."""
    profile = tmp_path_factory.mktemp("chromium-profile")
    process = subprocess.Popen(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--no-first-run", "--remote-debugging-address=127.0.0.1", "--remote-debugging-port=0",
         f"--user-data-dir={profile}", f"--window-size={WIDTHS[0]},{HEIGHT}", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    port_file = profile / "DevToolsActivePort"
    deadline = time.monotonic() + 60
    while not (port_file.is_file() and port_file.read_text().strip()):
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"chromium did not open its DevTools port (exit code {process.poll()})")
        time.sleep(0.1)
    try:
        yield f"http://127.0.0.1:{port_file.read_text().split()[0]}"
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def open_page(browser: str, path: Path, width: int = WIDTHS[0]) -> DevToolsPage:
    """Load ``path`` in the first tab, ``width`` CSS px wide, with console, log and page events on;
    wait for its load event."""
    with urllib.request.urlopen(f"{browser}/json/list", timeout=30) as response:
        target = next(t for t in json.load(response) if t["type"] == "page")
    page = DevToolsPage(target["webSocketDebuggerUrl"])
    for domain in ("Page", "Runtime", "Log"):
        page.call(f"{domain}.enable")
    page.call("Emulation.setDeviceMetricsOverride", width=width, height=HEIGHT, deviceScaleFactor=1, mobile=False)
    page.events.clear()
    page.call("Page.navigate", url=path.resolve().as_uri())
    page.wait_for("Page.loadEventFired")
    return page


IMAGES = """Promise.all([...document.images].map(i => i.decode().then(
    () => ({alt: i.alt, width: i.naturalWidth, height: i.naturalHeight}),
    e => ({alt: i.alt, width: 0, height: 0, error: String(e)}))))"""


#: What the page shows, measured in the browser: widths in CSS px, the topology key's font size, and
#: the story (the summary, the effects table's names, the failures located).
LAYOUT = """(() => {
  const px = e => e.getBoundingClientRect().width;
  const probe = document.createElement('span');
  probe.style.cssText = 'display:inline-block;width:6ch;visibility:hidden';
  const rules = [...document.querySelectorAll('td.rule')].map(td => {
    const width = px(td); td.appendChild(probe); const sixChars = px(probe); probe.remove();
    return {width, sixChars};
  });
  const wide = [...document.body.querySelectorAll('*')].filter(e => e.getBoundingClientRect().right > innerWidth + 0.5)
    .map(e => e.tagName + '.' + e.className);
  const effects = [...document.querySelectorAll('table.effects tbody tr')].map(tr =>
    [tr.querySelector('.effect').textContent, tr.querySelector('small').textContent]);
  const summary = document.querySelector('.summary');
  return {scrollWidth: document.documentElement.scrollWidth, innerWidth, rules, wide,
          key: [...document.querySelectorAll('ul.key li')].map(li => parseFloat(getComputedStyle(li).fontSize)),
          summary: summary ? summary.textContent : '', effects,
          located: document.querySelectorAll('ul.locations li').length};
})()"""


@pytest.mark.parametrize("width", WIDTHS)
def test_the_report_fits_the_window_renders_every_figure_tells_one_story_and_is_screenshotted(
        browser, tmp_path_factory, tmp_path, record_property, width):
    html = report_page(tmp_path_factory.getbasetemp() / "report-run")
    path = tmp_path / "report.html"
    path.write_text(html, encoding="utf-8")
    page = open_page(browser, path, width)
    try:
        images = page.call("Runtime.evaluate", expression=IMAGES, awaitPromise=True, returnByValue=True)["result"]["value"]
        layout = page.call("Runtime.evaluate", expression=LAYOUT, returnByValue=True)["result"]["value"]
        page.call("Runtime.evaluate", expression="0")  # let events queued during the decoding arrive
        assert page.errors() == []
        size = page.call("Page.getLayoutMetrics")["cssContentSize"]
        shot = page.call("Page.captureScreenshot", format="png", captureBeyondViewport=True,
                         clip={"x": 0, "y": 0, "width": width, "height": size["height"], "scale": 1})
    finally:
        page.ws.close()
    screenshot = tmp_path / f"report-{width}.png"
    screenshot.write_bytes(base64.b64decode(shot["data"]))
    record_property(f"screenshot-{width}", str(screenshot))
    if os.environ.get("REPORT_SCREENSHOTS"):
        folder = Path(os.environ["REPORT_SCREENSHOTS"])
        folder.mkdir(parents=True, exist_ok=True)
        shutil.copy(screenshot, folder / screenshot.name)
    print(f"report screenshot at {width} px: {screenshot}")
    # every figure decodes
    assert len(images) == html.count("<img ")
    kinds = {i["alt"].split(":")[0] for i in images}
    assert kinds == {"measured vs model", "flow topology of case", "test RMSE across versions of case"}
    for image in images:
        assert image["width"] > 100 and image["height"] > 50, image
    picture = Image.open(io.BytesIO(screenshot.read_bytes()))
    assert picture.width == width and picture.height > 2 * HEIGHT  # the whole page, figures included
    assert len(picture.convert("RGB").getcolors(maxcolors=1 << 20)) > 100
    # it fits: nothing wider than the window, a rule never squeezed to a word a line
    assert layout["scrollWidth"] <= layout["innerWidth"] and layout["wide"] == [], layout["wide"]
    assert layout["rules"] and all(rule["width"] >= rule["sixChars"] for rule in layout["rules"]), layout["rules"]
    assert len(layout["key"]) >= 7 and min(layout["key"]) >= 12
    # one story: the summary names an effect of the effects table, and an effect reported missing
    # comes with the failure it explains located on the flow path
    assert layout["summary"] and layout["effects"]
    assert any(name in layout["summary"] or label in layout["summary"] for name, label in layout["effects"]), layout
    if layout["summary"].startswith("Missing:") and not layout["located"]:
        pytest.xfail("the diagnosis reports a missing effect but located no failure (issue 30: fixed in "
                     "service/diagnosis/, not in the report)")
    assert not layout["summary"].startswith("Missing:") or layout["located"] > 0


def test_the_error_detection_sees_a_blocked_external_image_and_a_blocked_script(browser, tmp_path_factory, tmp_path):
    html = report_page(tmp_path_factory.getbasetemp() / "report-run")
    intruders = '<img alt="x" src="https://example.invalid/x.png"><script>console.error("x")</script>'
    broken = html.replace("</body>", intruders + "</body>")
    path = tmp_path / "broken.html"
    path.write_text(broken, encoding="utf-8")
    page = open_page(browser, path)
    try:
        page.call("Runtime.evaluate", expression="0")
        errors = page.errors()
    finally:
        page.ws.close()
    assert any("example.invalid" in e for e in errors), errors
    assert any("script" in e.lower() for e in errors), errors
