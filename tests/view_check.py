#!/usr/bin/env python3
"""The viewer page (bounce view) in headless Chromium on the Cornell box: screenshots of L, E alone,
KE alone and K2E alone, checked against what the physics says, not against earlier screenshots:

- E alone shows only the light: a few percent of the pixels lit, the light's centre bright, the
  blocks black;
- the block faces that look at the red wall (the tall block's) and at the green wall (the short
  block's) do not see the light, so KE leaves them dark; from K2E on they carry the walls' colour
  (light reflected once by a coloured wall): red over green well above the light's own 17:12 on the
  first, green over red above the light's 12:17 on the second;
- the screenshots differ where they should (E from L, KE from K2E), and the page loads its three.js
  and bake with no network.

usage: view_check.py BOUNCE SOURCE_DIR OUT_DIR
Exit 77 (skipped) when no browser is installed.
"""
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import zlib

W, H = 800, 600
failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def read_png(path):
    """8-bit RGB or RGBA, not interlaced (what Chromium writes): rows of (r, g, b) tuples."""
    d = open(path, "rb").read()
    assert d[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat, w = 8, b"", 0
    while pos < len(d):
        n, kind = struct.unpack(">I4s", d[pos:pos + 8])
        body = d[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0, (depth, ctype, interlace)
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append([tuple(line[x * bpp:x * bpp + 3]) for x in range(w)])
        prev = line
    return rows


def lin(v):
    v /= 255.0
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def patch_mean(img, x, y, r=2):
    """Linear RGB mean over a (2r+1)^2 window at (x, y)."""
    s = [0.0, 0.0, 0.0]
    n = 0
    for yy in range(int(round(y)) - r, int(round(y)) + r + 1):
        for xx in range(int(round(x)) - r, int(round(x)) + r + 1):
            for c in range(3):
                s[c] += lin(img[yy][xx][c])
            n += 1
    return [v / n for v in s]


def main():
    bounce, src, out = sys.argv[1:4]
    browser = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
    if not browser:
        print("SKIP: no browser: install Debian's chromium (scripts/setup.sh does) to run this test")
        sys.exit(77)
    os.makedirs(out, exist_ok=True)
    page = os.path.join(out, "cornell.html")
    r = subprocess.run([bounce, "view", os.path.join(src, "meshes/cornell-box.obj"), "--unit", "mm", "-q",
                        "--patches", "400", "--ff-visibility", "rays",   # the page is tested, not visibility
                        "-o", page], capture_output=True, text=True)
    check(r.returncode == 0, "bounce view wrote the page (exit %d)" % r.returncode)
    if r.returncode:
        print(r.stderr)
        sys.exit(1)
    # bad input: a file that is not a .glb gives a clear error, a non-zero exit and no page
    bad, badpage = os.path.join(out, "not-a-bake.glb"), os.path.join(out, "bad.html")
    open(bad, "w").write("solid nothing\n")
    if os.path.exists(badpage):
        os.remove(badpage)
    rb = subprocess.run([bounce, "view", bad, "-o", badpage], capture_output=True, text=True)
    check(rb.returncode != 0 and "not a glTF binary" in rb.stderr and bad in rb.stderr and not os.path.exists(badpage),
          "a .glb that is not one: exit %d, '%s', no page" % (rb.returncode, rb.stderr.strip()[-120:]))
    # a .glb cut short: its header's length word says more than the file holds
    cut = os.path.join(out, "cut.glb")
    with open(cut, "wb") as fh:
        fh.write(b"glTF" + struct.pack("<II", 2, 4096) + struct.pack("<I", 8) + b"JSON" + b'{"asset":')
    rc = subprocess.run([bounce, "view", cut, "-o", badpage], capture_output=True, text=True)
    check(rc.returncode != 0 and "truncated" in rc.stderr and "4096" in rc.stderr and not os.path.exists(badpage),
          "a .glb cut short: exit %d, '%s', no page" % (rc.returncode, rc.stderr.strip()[-120:]))
    html = open(page, encoding="utf-8").read()
    check("http://" not in html.split("<script type=\"importmap\">")[0] and "https://" not in html.split("<script")[0],
          "the page loads nothing from the network")
    if os.environ.get("BN_TEST_SKIP_SLOW"):   # the sanitized run: bounce's C above is what it checks
        print("SKIP (the browser part, in the sanitized run): the page's screenshots are JavaScript and "
              "SwiftShader, checked by the normal run")
        sys.exit(1 if failures else 0)
    url = "file://" + os.path.abspath(page)
    # one browser for every view: each opens in a new tab (a launch costs ~5 s, a tab well under one)
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import cdp
    with cdp.Page(browser, "about:blank", (W, H)) as tab:
        shots = views(tab, url, out)
        if shots:
            physics(shots)
            url_round_trip(tab, url, page)
    bake_again(bounce, page, out)
    print("%d failures" % len(failures))
    sys.exit(1 if failures else 0)


def mean_diff(a, b):
    return sum(abs(p[c] - q[c]) for ra, rb in zip(a, b) for p, q in zip(ra, rb) for c in range(3)) / (
        3.0 * 255 * len(a) * len(a[0]))


def lit_fraction(img):
    return sum(1 for row in img for p in row if max(p) > 12) / float(len(img) * len(img[0]))


def physics(shots):
    """What the light's paths say about the screenshots (see the module's doc)."""
    light, red_face, green_face, floor = shots["probes"]
    fe, fl = lit_fraction(shots["E"]), lit_fraction(shots["L"])
    check(fe < 0.03, "E alone: %.2f%% of the pixels lit (only the light)" % (100 * fe))
    check(fl > 0.3, "L: %.1f%% of the pixels lit" % (100 * fl))
    check(min(patch_mean(shots["E"], *light)) > 0.5, "E alone: the light's centre is bright")
    for nm, p in (("red-facing", red_face), ("green-facing", green_face), ("floor", floor)):
        check(max(patch_mean(shots["E"], *p)) < 0.01, "E alone: the %s probe is black" % nm)
    ke_red, ke_green = patch_mean(shots["KE"], *red_face), patch_mean(shots["KE"], *green_face)
    ke_floor = patch_mean(shots["KE"], *floor)
    k2_red, k2_green = patch_mean(shots["K2E"], *red_face), patch_mean(shots["K2E"], *green_face)
    print("linear RGB: KE red-facing %s, green-facing %s, floor %s; K2E red-facing %s, green-facing %s"
          % tuple(["(%.3f %.3f %.3f)" % tuple(v) for v in (ke_red, ke_green, ke_floor, k2_red, k2_green)]))
    check(max(ke_red) < 0.1 * max(ke_floor) and max(ke_green) < 0.1 * max(ke_floor),
          "KE alone: the block faces toward the coloured walls see no light (dark beside the lit floor)")
    check(k2_red[0] > 3 * (17.0 / 12.0) * k2_red[1] and k2_red[0] > 0.02,
          "K2E: the tall block's face toward the red wall is red (R/G %.2f, the light's 1.42)"
          % (k2_red[0] / max(k2_red[1], 1e-9)))
    check(k2_green[1] > 2 * (12.0 / 17.0) * k2_green[0] and k2_green[1] > 0.02,
          "K2E: the short block's face toward the green wall is green (G/R %.2f, the light's 0.71)"
          % (k2_green[1] / max(k2_green[0], 1e-9)))
    # the simplified copy keeps the colour bleeding where the full mesh has it (the same independent answer)
    m_red, m_green = patch_mean(shots["K2E-moving"], *red_face), patch_mean(shots["K2E-moving"], *green_face)
    check(m_red[0] > 3 * (17.0 / 12.0) * m_red[1] and m_green[1] > 2 * (12.0 / 17.0) * m_green[0],
          "K2E, simplified copy: red-facing R/G %.2f, green-facing G/R %.2f"
          % (m_red[0] / max(m_red[1], 1e-9), m_green[1] / max(m_green[0], 1e-9)))
    check(mean_diff(shots["L"], shots["E"]) > 0.02, "L and E alone differ (%.3f)" % mean_diff(shots["L"], shots["E"]))
    check(mean_diff(shots["KE"], shots["K2E"]) > 0.01,
          "KE and K2E alone differ (%.3f)" % mean_diff(shots["KE"], shots["K2E"]))


def open_view(tab, url):
    """Opens a view of the page and waits until it has drawn (its title says ready); the DOM then."""
    tab.goto(url)
    ok = tab.wait("document.title === 'ready'", timeout=120) is not None
    check(ok, "the page drew %s" % url.rsplit("#", 1)[-1])
    return tab.dom() if ok else ""


def shoot(tab, url, out, name):
    """A screenshot of a view, kept as OUT/view-NAME.png and read back: its rows of pixels (None if none)."""
    open_view(tab, url)
    png = os.path.join(out, "view-%s.png" % name)
    with open(png, "wb") as fh:
        fh.write(tab.screenshot())
    return read_png(png)


def views(tab, url, out):
    """The probes' pixels and the screenshots of L, E, KE, K2E (and K2E's simplified copy); None on failure."""
    # where the probes land: the light's centre, the tall block's face toward the red wall, the short
    # block's face toward the green wall (centroids, metres), the floor between the blocks
    probes = [(0.278, 0.5485, 0.2795), (0.4475, 0.165, 0.3265), (0.106, 0.0825, 0.145), (0.28, 0.0, 0.06)]
    q = ";".join(",".join("%g" % c for c in p) for p in probes)
    dom = open_view(tab, url + FIXED + "lod=1&probe=" + q)
    mark = '<pre id="probe" style'
    check(mark in dom, "the page ran (its probe output is in the DOM)")
    if mark not in dom:
        return None
    txt = dom.rsplit(mark, 1)[1].split(">", 1)[1].split("</pre>")[0]
    pts = [tuple(float(v) for v in ln.split()) for ln in txt.strip().splitlines()]
    # the simplified copy drawn while the camera moves (forced here with #lod=1; by default above 20k triangles)
    m = re.search(r'id="info">(\d+) vertices, (\d+) triangles;[^<]*?; (\d+) while the camera moves', dom)
    check("no antialiasing (software WebGL)" in dom,
          "SwiftShader is recognised as software WebGL: antialiasing off by default (a third of the frame rate)")
    check(m is not None and int(m.group(3)) < int(m.group(2)),
          "#lod=1: a simplified copy for when the camera moves (%s)" % (", ".join(m.groups()) if m else "none"))
    shots = {"probes": pts}
    for name, frag in (("L", ""), ("E", "terms=E"), ("KE", "terms=KE&ev=3"), ("K2E", "terms=K2E&ev=3"),
                       ("K2E-moving", "terms=K2E&ev=3&lod=1&moving=1")):
        shots[name] = shoot(tab, url + FIXED + frag, out, name)
    return shots


def k2e_auto_ev(glb):
    """The exposure bounce's rule gives K2E alone: its 99th percentile vertex luminance at 0.9 (here, from the
    bake's own _K2E attribute, read by the test's glTF reader)."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from gltf_check import accessor, read_glb
    gl, b = read_glb(glb)
    at = gl["meshes"][0]["primitives"][0]["attributes"]
    v, _ = accessor(gl, b, at["_K2E"])
    lum = sorted(y for y in (0.2126 * v[i] + 0.7152 * v[i + 1] + 0.0722 * v[i + 2] for i in range(0, len(v), 3)) if y > 0)
    return math.log2(0.9 / lum[int(0.99 * (len(lum) - 1))])


FIXED = "#panel=0&size=%dx%d&" % (W, H)   # the same canvas and projection in every view


def url_round_trip(tab, url, page):
    """The address follows the view: a page opened at a view (terms, automatic exposure, camera, folded panel)
    links to that view, and the link opens the same picture."""
    out = os.path.dirname(page)
    state = "terms=K2E&ev=auto&cam=0.52,0.41,-0.62,0.27,0.2,0.3"
    dom = open_view(tab, url + FIXED + state)
    m = re.search(r'<a id="link" href="#([^"]*)"', dom)
    link = m.group(1).replace("&amp;", "&") if m else ""
    want = dict(kv.split("=", 1) for kv in (FIXED[1:] + state).split("&") if kv)
    got = dict(kv.split("=", 1) for kv in link.split("&") if kv)
    check(all(got.get(k) == v for k, v in want.items()), "the page's link holds its view: %s" % link)
    ev = re.search(r'id="evtext">([-0-9.]+)<', dom)
    kept = page[:-5] + ".bake.glb"   # bounce view keeps its bake beside the page, as bake_again reads it
    check(os.path.exists(kept), "bounce view kept the bake beside the page (%s)" % os.path.basename(kept))
    if ev and os.path.exists(kept):
        want_ev = k2e_auto_ev(kept)
        check(abs(float(ev.group(1)) - want_ev) < 0.06,
              "ev=auto on K2E alone: %s EV, its 99th percentile luminance at 0.9 says %.2f" % (ev.group(1), want_ev))
    shots = [shoot(tab, url + frag, out, "link-%d" % i) for i, frag in enumerate((FIXED + state, "#" + link))]
    check(mean_diff(shots[0], shots[1]) < 1e-3, "the link opens the same picture (mean difference %.2g)"
          % mean_diff(shots[0], shots[1]))
    dom = open_view(tab, url + "#panel=folded")
    check('id="body" style="display: none;"' in dom and "panel=folded" in dom,
          "#panel=folded folds the panel, and its link says so")


def bake_again(bounce, page, out):
    """The bake kept beside the page is shown again without solving."""
    kept, again = page[:-5] + ".bake.glb", os.path.join(out, "again.html")
    r = subprocess.run([bounce, "view", kept, "-o", again], capture_output=True, text=True)
    check(r.returncode == 0 and "transport" not in r.stderr and os.path.exists(again),
          "bounce view of the kept bake builds the page without solving (exit %d)" % r.returncode)


if __name__ == "__main__":
    main()
