"""Drives chassisd's live page in headless Chromium over the DevTools protocol, for
tests/suite/websocket.rs.

    page.py CHROMIUM DAEMON_PORT OUT_DIR [zones]

Loads http://127.0.0.1:DAEMON_PORT/ with every other host unresolvable, waits for the page
to connect, takes a screenshot, holds the jog pad's forward button for 2 s, takes another,
clicks the plot to set a goal, waits for the vehicle to reach it, releases a held button by
taking the focus away, and prints one JSON object with what it saw, with every request the
page made (the DevTools Network domain: documents, scripts, WebSockets).

With `refused TOKEN` (a daemon run with that token and `max_clients = 1`): opens the page
with a wrong token, with none, and with the right one while another client holds the only
place, and prints what the page said each time, then how long it took to connect by itself
once the place was free.

With `zones` (a daemon run with tests/common/zones.rs's yard): waits for the zones and the
safety envelope, reads the plot's pixels inside the pond and beside it, then holds forward
towards the pond until the vehicle stops, and prints what the page showed.
"""

import base64
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request

from websockets.sync.client import connect


class Page:
    def __init__(self, ws):
        self.ws = ws
        self.next_id = 0
        self.requests = []

    def call(self, method, **params):
        self.next_id += 1
        mine = self.next_id
        self.ws.send(json.dumps({"id": mine, "method": method, "params": params}))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("method") == "Network.requestWillBeSent":
                self.requests.append(reply["params"]["request"]["url"])
            elif reply.get("method") == "Network.webSocketCreated":
                self.requests.append(reply["params"]["url"])
            if reply.get("id") == mine:
                if "error" in reply:
                    raise RuntimeError("%s: %s" % (method, reply["error"]))
                return reply.get("result", {})

    def js(self, expression):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        return result.get("result", {}).get("value")

    def wait(self, expression, seconds, what):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if self.js(expression):
                return
            time.sleep(0.1)
        raise RuntimeError("timed out waiting for " + what)

    def screenshot(self, path):
        data = self.call("Page.captureScreenshot", format="png")["data"]
        with open(path, "wb") as f:
            f.write(base64.b64decode(data))

    def mouse(self, kind, x, y):
        self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", buttons=1 if kind != "mouseReleased" else 0, clickCount=1, pointerType="mouse")


def pose(page):
    return page.js("window.chassisdPage.pose")


def open_page(page, port):
    """Loads the daemon's page and waits for it to connect and show a pose."""
    # A laptop's screen: the whole page, the time plots under the map included.
    page.call("Emulation.setDeviceMetricsOverride", width=1280, height=800, deviceScaleFactor=1, mobile=False)
    page.call("Page.enable")
    page.call("Network.enable")
    page.call("Page.navigate", url="http://127.0.0.1:%d/" % port)
    page.wait("window.chassisdPage && window.chassisdPage.connected && window.chassisdPage.pose !== null", 20, "the page to connect")


def run(page, port, out):
    open_page(page, port)
    page.wait("Object.keys(window.chassisdPage.diagnostics).length >= 4", 10, "the diagnostics")
    start = pose(page)
    page.screenshot(os.path.join(out, "page-start.png"))

    # Hold the jog pad's forward button for 2 s.
    forward = page.js("(() => { const r = document.querySelector('#jog button[data-v=\"1\"]').getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; })()")
    page.mouse("mouseMoved", *forward)
    page.mouse("mousePressed", *forward)
    time.sleep(2.0)
    held = page.js("window.chassisdPage.jogging")
    page.mouse("mouseReleased", *forward)
    released_at = time.monotonic()
    page.wait("window.chassisdPage.odom && Math.abs(window.chassisdPage.odom.v) < 0.005", 5, "the vehicle to stop after the release")
    stop_s = time.monotonic() - released_at
    jogged = pose(page)
    page.screenshot(os.path.join(out, "page-jogged.png"))

    # Click the plot 2 m to the left of the vehicle: a goal there.
    target = [jogged["x"], jogged["y"] + 2.0]
    at = page.js("window.chassisdPage.toScreen(%f, %f)" % tuple(target))
    page.mouse("mouseMoved", *at)
    page.mouse("mousePressed", *at)
    page.mouse("mouseReleased", *at)
    page.wait("window.chassisdPage.plan.length === 2", 5, "the goal's plan")
    page.wait("(() => { const p = window.chassisdPage.pose, o = window.chassisdPage.odom; return Math.hypot(p.x - %f, p.y - %f) < 0.05 && Math.abs(o.v) < 0.005 && Math.abs(o.w) < 0.005; })()" % tuple(target), 40, "the vehicle at the goal")
    page.wait("window.chassisdPage.plan.length === 0", 5, "the plan to clear")
    arrived = pose(page)
    page.screenshot(os.path.join(out, "page.png"))

    # Hold a button, then the page loses the focus: the jog stops by itself.
    page.mouse("mouseMoved", *forward)
    page.mouse("mousePressed", *forward)
    time.sleep(1.0)
    page.js("window.dispatchEvent(new Event('blur'))")
    blurred_at = time.monotonic()
    page.wait("!window.chassisdPage.jogging", 2, "the jog to stop on blur")
    page.wait("window.chassisdPage.odom && Math.abs(window.chassisdPage.odom.v) < 0.005", 5, "the vehicle to stop after the blur")
    blur_stop_s = time.monotonic() - blurred_at
    page.mouse("mouseReleased", *forward)
    events = page.js("window.chassisdPage.events")
    # The last minutes: a sample a second of each series, speed and σ among them.
    page.wait("window.chassisdPage.history.speed.length >= 5", 10, "five history samples")
    history = page.js("window.chassisdPage.history")
    panels = page.js("Object.fromEntries(['link', 'pose', 'gnss', 'battery', 'drives', 'nav', 'envelope'].map((id) => [id, document.getElementById(id).textContent]))")
    colours = page.js("Object.fromEntries(['gnss', 'drives', 'nav', 'battery'].map((id) => { const e = document.getElementById(id); const s = e.querySelector('span') || e; return [id, getComputedStyle(s).color]; }))")
    print(json.dumps({
        "start": start, "held": held, "jogged": jogged, "stop_s": stop_s,
        "target": target, "arrived": arrived, "blur_stop_s": blur_stop_s,
        "events": events, "gnss": page.js("window.chassisdPage.diagnostics.gnss.message"),
        "battery": page.js("window.chassisdPage.battery && window.chassisdPage.battery.voltage"),
        "axis": page.js("window.chassisdPage.axisLabels"), "scale": page.js("window.chassisdPage.scaleBar"),
        "history": history, "panels": panels, "colours": colours,
        "requests": page.requests,
    }), flush=True)


def run_refused(page, port, token):
    """The page told why it cannot connect: a wrong token, none, too many clients; and it
    connects by itself once a place is free."""
    page.call("Page.enable")

    def fresh(url):
        # Through a blank page, so no wait is answered by the last page's state.
        page.call("Page.navigate", url="about:blank")
        page.wait("!window.chassisdPage", 10, "a blank page")
        page.call("Page.navigate", url=url)

    seen = {}
    for name, query in [("wrong", "?token=not-it"), ("none", "")]:
        fresh("http://127.0.0.1:%d/%s" % (port, query))
        page.wait("window.chassisdPage && window.chassisdPage.link.includes('trying again')", 10, "the page's reason (%s)" % name)
        seen[name] = page.js("document.getElementById('link').textContent")
    # Another client with the token takes the only place (websocket.max_clients = 1).
    with connect("ws://127.0.0.1:%d/?token=%s" % (port, token)) as other:
        fresh("http://127.0.0.1:%d/?token=%s" % (port, token))
        page.wait("window.chassisdPage && window.chassisdPage.link.includes('trying again')", 10, "the page's reason (full)")
        seen["full"] = page.js("document.getElementById('link').textContent")
        page.screenshot(os.path.join(sys.argv[3], "page-refused.png"))
    # The place is free again: the page, asking every 5 s, connects by itself.
    began = time.monotonic()
    page.wait("window.chassisdPage && window.chassisdPage.connected", 20, "the page to connect once a place is free")
    seen["reconnect_s"] = time.monotonic() - began
    seen["after"] = page.js("document.getElementById('link').textContent")
    print(json.dumps(seen), flush=True)


def pixel(page, x, y):
    """The plot's colour (RGBA) at map point (x, y)."""
    return page.js("(() => { const [px, py] = window.chassisdPage.toCanvas(%f, %f); "
                   "return Array.from(document.getElementById('plot').getContext('2d')"
                   ".getImageData(Math.round(px), Math.round(py), 1, 1).data); })()" % (x, y))


def run_zones(page, port, out):
    open_page(page, port)
    page.wait("window.chassisdPage.zones.length === 4 && window.chassisdPage.envelope && window.chassisdPage.envelope.gate === 'open'", 30, "the zones and an open gate")
    zones = page.js("window.chassisdPage.zones.map((z) => ({kind: z.kind, name: z.name, points: z.points.length}))")
    at_rest = page.js("window.chassisdPage.envelope")
    page.js("draw()")
    inside, beside = pixel(page, 5.5, 0.5), pixel(page, 5.5, 3.5)
    page.screenshot(os.path.join(out, "page-zones.png"))

    # Hold forward (0.3 m/s) towards the pond, 4 m ahead, until the vehicle has stopped.
    forward = page.js("(() => { const r = document.querySelector('#jog button[data-v=\"1\"]').getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; })()")
    page.mouse("mouseMoved", *forward)
    page.mouse("mousePressed", *forward)
    page.wait("window.chassisdPage.odom && window.chassisdPage.odom.v > 0.25", 5, "the jog to start")
    moving = page.js("window.chassisdPage.envelope")
    page.wait("window.chassisdPage.odom && Math.abs(window.chassisdPage.odom.v) < 0.005", 30, "the vehicle to stop before the pond")
    time.sleep(1.0)
    stopped = page.js("window.chassisdPage.envelope")
    pose = page.js("window.chassisdPage.pose")
    # The latched stop's reason, while the button is still held (a release re-arms).
    try:
        page.wait("document.getElementById('drives').textContent.includes('pond')", 5, "the stop's reason")
    except RuntimeError:
        pass
    drives = page.js("document.getElementById('drives').textContent")
    page.mouse("mouseReleased", *forward)
    page.js("draw()")
    page.screenshot(os.path.join(out, "page-zones-stopped.png"))
    print(json.dumps({
        "zones": zones, "at_rest": at_rest, "moving": moving, "stopped": stopped, "pose": pose,
        "inside": inside, "beside": beside,
        "panel": page.js("document.getElementById('envelope').textContent"),
        "margin_text": page.js("document.getElementById('margin').textContent"),
        "drives": drives,
    }), flush=True)


def main():
    chromium, port, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    mode = sys.argv[4:]
    profile = tempfile.mkdtemp(prefix="chassisd-page-")
    browser = subprocess.Popen([
        chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
        "--no-first-run", "--disable-background-networking", "--disable-component-update",
        "--window-size=1280,760", "--remote-debugging-port=0", "--user-data-dir=" + profile,
        # Any host but the daemon's fails to resolve: the page must need none.
        "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
        "about:blank",
    ], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        devtools = os.path.join(profile, "DevToolsActivePort")
        deadline = time.monotonic() + 30
        while not os.path.exists(devtools) and time.monotonic() < deadline:
            time.sleep(0.1)
        debug_port = open(devtools).read().split()[0]
        targets = json.load(urllib.request.urlopen("http://127.0.0.1:%s/json/list" % debug_port))
        url = [t for t in targets if t["type"] == "page"][0]["webSocketDebuggerUrl"]
        with connect(url, max_size=None) as ws:
            if mode == ["zones"]:
                run_zones(Page(ws), port, out)
            elif mode[:1] == ["refused"]:
                run_refused(Page(ws), port, mode[1])
            else:
                run(Page(ws), port, out)
    finally:
        browser.terminate()
        browser.wait(timeout=10)
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    main()
