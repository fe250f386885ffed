"""A page in headless Chromium driven over the DevTools protocol on a pipe (--remote-debugging-pipe: no
network, no websocket library): open a page, evaluate expressions in it until one holds. Used by the live
page's test (tests/live_check.py) and the viewer's benches (bench/view_fps.py, bench/live_bench.py).

    with Page(browser, url) as page:
        page.wait("document.title === 'ready'", timeout=60)
        text = page.eval("document.getElementById('x').textContent")
        page.goto(other_url)                  # a new tab in the same browser (one launch for many pages)
        png = page.screenshot()               # PNG bytes of the viewport after the next two frames
"""
import base64
import json
import os
import shutil
import subprocess
import time


def find_browser():
    return next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)


class Page:
    def __init__(self, browser, url, size=(800, 600)):
        r1, w1 = os.pipe()   # the browser reads commands on its fd 3 ...
        r2, w2 = os.pipe()   # ... and answers on its fd 4

        def fds():
            os.dup2(r1, 3)
            os.dup2(w2, 4)

        self.proc = subprocess.Popen([browser, "--headless", "--no-sandbox", "--use-gl=swiftshader",
                                      "--enable-unsafe-swiftshader", "--window-size=%d,%d" % size,
                                      "--hide-scrollbars", "--remote-debugging-pipe", "about:blank"],
                                     preexec_fn=fds, pass_fds=(3, 4), stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(r1)
        os.close(w2)
        self.out, self.inp, self.buf, self.n = os.fdopen(w1, "wb"), r2, b"", 0
        self.target, self.size = None, size
        self.goto(url)

    def goto(self, url):
        """Opens url in a new tab (a full load, even where only the fragment differs) and closes the last one.
        The tab's viewport is the size asked for (the window's, less the headless browser's own frame, is not)."""
        old = self.target
        self.target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": self.target, "flatten": True})["sessionId"]
        self.call("Emulation.setDeviceMetricsOverride", {"width": self.size[0], "height": self.size[1],
                                                         "deviceScaleFactor": 1, "mobile": False}, self.session)
        self.call("Page.navigate", {"url": url}, self.session)
        if old:
            self.call("Target.closeTarget", {"targetId": old})

    def screenshot(self):
        """The viewport as PNG bytes, after two animation frames (what is drawn has reached the screen)."""
        self.call("Runtime.evaluate", {"expression": "new Promise((r) => requestAnimationFrame(() => "
                                       "requestAnimationFrame(() => r(1))))", "awaitPromise": True}, self.session)
        return base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"}, self.session)["data"])

    def dom(self):
        return self.eval("document.documentElement.outerHTML")

    def call(self, method, params=None, session=None):
        self.n += 1
        m = {"id": self.n, "method": method, "params": params or {}}
        if session:
            m["sessionId"] = session
        self.out.write(json.dumps(m).encode() + b"\0")
        self.out.flush()
        while True:
            while b"\0" in self.buf:
                msg, self.buf = self.buf.split(b"\0", 1)
                r = json.loads(msg)
                if r.get("id") == self.n:
                    return r.get("result", {})
            chunk = os.read(self.inp, 1 << 16)
            if not chunk:
                raise RuntimeError("the browser closed its pipe")
            self.buf += chunk

    def eval(self, expression):
        """The value of a JavaScript expression in the page (None when it throws)."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True}, self.session)
        return r.get("result", {}).get("value")

    def wait(self, expression, timeout=60.0, poll=0.1):
        """Evaluates until the expression is truthy; its value, or None after timeout seconds."""
        t0 = time.time()
        while time.time() - t0 < timeout:
            v = self.eval(expression)
            if v:
                return v
            time.sleep(poll)
        return None

    def close(self):
        try:
            self.call("Browser.close")
        except Exception:
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
