#!/usr/bin/env python3
"""Frames per second of the viewer page (bounce view) in headless Chromium, measured by the page
itself (#fps=1: the camera turns for two seconds of real time under requestAnimationFrame and the
title becomes "fps N"), read over the DevTools protocol on a pipe (--remote-debugging-pipe: no
network, no websocket library). Prints one line per page: PAGE fps.

usage: view_fps.py PAGE.html [...]   (extra hash settings after a '#', e.g. page.html#aa=1)
"""
import json
import os
import shutil
import subprocess
import sys
import time


def measure(browser, url, timeout=90):
    r1, w1 = os.pipe()   # the browser reads commands on its fd 3 ...
    r2, w2 = os.pipe()   # ... and answers on its fd 4

    def fds():
        os.dup2(r1, 3)
        os.dup2(w2, 4)

    p = subprocess.Popen([browser, "--headless", "--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
                          "--window-size=800,600", "--remote-debugging-pipe", "about:blank"],
                         preexec_fn=fds, pass_fds=(3, 4), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(r1)
    os.close(w2)
    out, inp, buf, n = os.fdopen(w1, "wb"), r2, b"", [0]

    def call(method, params=None, session=None):
        nonlocal buf
        n[0] += 1
        m = {"id": n[0], "method": method, "params": params or {}}
        if session:
            m["sessionId"] = session
        out.write(json.dumps(m).encode() + b"\0")
        out.flush()
        while True:
            while b"\0" in buf:
                msg, buf = buf.split(b"\0", 1)
                r = json.loads(msg)
                if r.get("id") == n[0]:
                    return r.get("result", {})
            chunk = os.read(inp, 65536)
            if not chunk:
                raise RuntimeError("the browser closed its pipe")
            buf += chunk

    try:
        target = call("Target.createTarget", {"url": url})["targetId"]
        session = call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        t0, title = time.time(), ""
        while time.time() - t0 < timeout and not title.startswith("fps"):
            time.sleep(0.25)
            title = call("Runtime.evaluate", {"expression": "document.title", "returnByValue": True},
                         session).get("result", {}).get("value", "")
        return float(title.split()[1]) if title.startswith("fps") else float("nan")
    finally:
        try:
            call("Browser.close")
        except Exception:
            pass
        p.wait(timeout=20)


def main():
    browser = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
    if not browser:
        sys.exit("no browser (Debian's chromium)")
    for page in sys.argv[1:]:
        path, _, extra = page.partition("#")
        url = "file://" + os.path.abspath(path) + "#fps=1&size=800x600" + ("&" + extra if extra else "")
        print("%s %.1f" % (page, measure(browser, url)))


if __name__ == "__main__":
    main()
