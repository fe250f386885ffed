#!/usr/bin/env python3
"""Frames per second of the viewer page (bounce view) in headless Chromium, measured by the page
itself (#fps=1: the camera turns for two seconds of real time under requestAnimationFrame and the
title becomes "fps N"), read over the DevTools protocol on a pipe (--remote-debugging-pipe: no
network, no websocket library: tests/cdp.py). Prints one line per page: PAGE fps.

usage: view_fps.py PAGE.html [...]   (extra hash settings after a '#', e.g. page.html#aa=1)
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
import cdp  # noqa: E402


def measure(browser, url, timeout=90):
    with cdp.Page(browser, url) as p:
        title = p.wait("document.title.startsWith('fps') && document.title", timeout, poll=0.25)
    return float(title.split()[1]) if title else float("nan")


def main():
    browser = cdp.find_browser()
    if not browser:
        sys.exit("no browser (Debian's chromium)")
    for page in sys.argv[1:]:
        path, _, extra = page.partition("#")
        url = "file://" + os.path.abspath(path) + "#fps=1&size=800x600" + ("&" + extra if extra else "")
        print("%s %.1f" % (page, measure(browser, url)))


if __name__ == "__main__":
    main()
