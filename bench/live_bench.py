#!/usr/bin/env python3
"""Update time per change of the live page (bounce view --live) in headless Chromium: the page itself
(#livebench=N) makes N changes, alternating a reflectance (the first material that does not emit, x0.9
and back) and an emitter's Le (x1.5 and back), and times each from the slider to the recoloured page:
the first view (rest estimated from the last term) and the exact one. Read over the DevTools protocol
(tests/cdp.py). Prints one markdown row per page:
| page | patches | links | rho: first view | rho: exact | Le | worker's share |

usage: live_bench.py PAGE.html [N]
"""
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
import cdp  # noqa: E402


def main():
    page, n = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 20
    browser = cdp.find_browser()
    if not browser:
        sys.exit("no browser (Debian's chromium)")
    url = "file://" + os.path.abspath(page) + "#panel=0&size=800x600&livebench=%d" % n
    with cdp.Page(browser, url) as p:
        text = p.wait("document.getElementById('livebench') && document.getElementById('livebench').textContent", 900)
        info = p.eval("document.getElementById('info').textContent") or ""
        live = p.eval("document.getElementById('livetime').textContent") or ""
    if not text:
        print("| %s | | | the page did not finish | | | |" % os.path.basename(page))
        return
    f = {m.group(1): (float(m.group(2)), float(m.group(3))) for m in re.finditer(r"(\w+) median ([\d.]+) max ([\d.]+)", text)}
    cell = lambda k: "%.1f (max %.1f)" % f[k] if k in f else "-"  # noqa: E731
    tris = re.search(r"(\d+) triangles", info)
    print("| %s | %s | %s | %s | %s | %s |" % (os.path.basename(page), tris.group(1) if tris else "?", cell("rho_first"),
                                          cell("rho"), cell("Le"), live.strip()))


if __name__ == "__main__":
    main()
