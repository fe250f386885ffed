#!/usr/bin/env python3
"""The live page (bounce view --live) against bounce's own solves, on a small Cornell box:

- dense F: the page's worker (web/live-worker.js under node, on the payload the page embeds) relit with
  the light x2 and a green-ish red wall equals `bounce solve` of the edited scene on the same F (the
  form-factor cache) term by term (E, KE, K2E, K3E to 1e-5, L to the solve's tolerance), and the edit
  changed the red wall's light;
- the hierarchy's links (tree, clusters, row scaling) at the file's materials: the worker's terms equal
  `bounce solve --transport hierarchical`'s (the same links: refinement is deterministic);
- both: the page's WebAssembly kernel (web/live-kernel.c) ran and its terms are the JavaScript loop's, bit
  for bit (the same operations in the same order);
- punctual lights (glTF KHR_lights_punctual, the Cornell box's light turned into a bulb and a spot):
  the worker's L at the file's lights equals the solve's L the page carries, and scaling them by 2
  doubles every term (they are bounce 1's source);
- --budget below the data: the page is built on fewer patches, says so, and fits;
- bad options: a clear error, exit 2, no page;
- in headless Chromium: the page set through its address (the same edits) shows the C solve's KE on a
  red-wall patch; moving the light's slider through the DOM by +1 EV doubles what it shows (K is linear).

usage: live_check.py BOUNCE SOURCE_DIR OUT_DIR
Exit 77 (skipped) without node; the Chromium part is skipped (said) without a browser.
"""
import csv
import json
import os
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cdp  # noqa: E402

failures = []
EDITS = {"Le": {"light": [34.0, 24.0, 8.0]}, "rho": {"red": [0.1, 0.6, 0.1]}}


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode:
        print("command failed (%d): %s\n%s" % (r.returncode, " ".join(cmd), r.stderr[-2000:]))
    return r


def read_csv(path):
    rows = [ln for ln in open(path) if not ln.startswith("#")]
    return list(csv.DictReader(rows))


def worker(src, page, edits, js=False):
    r = subprocess.run(["node", os.path.join(src, "tests/live_eval.js"), os.path.join(src, "web/live-worker.js"), page,
                        json.dumps(edits)] + (["js"] if js else []), capture_output=True, text=True)
    if r.returncode:
        print(r.stderr[-2000:])
        return None
    return json.loads(r.stdout)


def kernel_check(src, page, edits, w, what):
    """The page's WebAssembly kernel ran and gave the JavaScript loop's doubles, every term, every patch."""
    if not w["kernel"]:
        check(False, "%s: the page has a WebAssembly kernel (the build needs clang and wasm-ld: Debian's lld; "
              "scripts/setup.sh installs it)" % what)
        return
    j = worker(src, page, edits, js=True)
    same = j is not None and w["wasm"] and not j["wasm"] and all(a == b for s, t in zip(w["terms"], j["terms"])
                                                                 for a, b in zip(s, t))
    check(same, "%s: the WebAssembly kernel (%d bytes) gives the JavaScript loop's terms bit for bit (%d applications)" %
          (what, w["kernel"], w["applies"]))


def compare(rows, w, names, rel, what):
    """Worst |page - solve| / (|solve| + 1e-3 x the term's largest) over patches and channels, per term."""
    for k, name in names:
        t = w["terms"][k]
        top = max(abs(float(r[name + "_" + c])) for r in rows for c in "RGB") or 1.0
        worst = max(abs(t[3 * i + j] - float(r[name + "_" + c])) / (abs(float(r[name + "_" + c])) + 1e-3 * top)
                    for i, r in enumerate(rows) for j, c in enumerate("RGB"))
        check(worst <= rel, "%s: %s per patch within %g (worst %.2g)" % (what, name, rel, worst))


def dense_checks(bounce, src, out, base):
    page, cache = os.path.join(out, "dense.html"), os.path.join(out, "F.cache")
    r = run([bounce, "view", "--live"] + base + ["--cache", cache, "-q", "-o", page])
    check(r.returncode == 0 and os.path.exists(page), "view --live wrote the dense page")
    flags = ["--set-Le", "light=34,24,8", "--set-rho", "red=0.1,0.6,0.1"]
    relit, plain = os.path.join(out, "relit.csv"), os.path.join(out, "plain.csv")
    r1 = run([bounce, "solve"] + base + ["--cache", cache, "--tol", "1e-9"] + flags + ["-n", "3", "-q", "-o", relit])
    r2 = run([bounce, "solve"] + base + ["--cache", cache, "-n", "3", "-q", "-o", plain])
    w = worker(src, page, EDITS)
    if r1.returncode or r2.returncode or w is None:
        check(False, "the solves and the worker ran")
        return None
    rows, rows0 = read_csv(relit), read_csv(plain)
    check(len(rows) == len(w["terms"][0]) // 3, "the page has the solve's %d patches" % len(rows))
    compare(rows, w, [(0, "E"), (1, "KE"), (2, "K2E"), (3, "K3E")], 1e-5, "dense, relit")
    compare(rows, w, [(len(w["terms"]) - 1, "L")], 1e-4, "dense, relit")
    kernel_check(src, page, EDITS, w, "dense")
    red = [i for i, r in enumerate(rows) if r["material"] == "red"]
    ke0 = sum(float(rows0[i]["KE_G"]) for i in red)
    ke1 = sum(float(rows[i]["KE_G"]) for i in red)
    check(ke1 > 2 * ke0, "the edits changed the red wall's KE (green: %.4g -> %.4g)" % (ke0, ke1))
    return page, rows, red


def hierarchy_checks(bounce, src, out, base):
    page, ref = os.path.join(out, "hier.html"), os.path.join(out, "hier.csv")
    hb = base + ["--transport", "hierarchical"]
    r = run([bounce, "view", "--live"] + hb + ["-q", "-o", page])
    r2 = run([bounce, "solve"] + hb + ["--tol", "1e-9", "-n", "3", "-q", "-o", ref])
    w = worker(src, page, {}) if r.returncode == 0 else None
    if r2.returncode or w is None:
        check(False, "the hierarchical page, its solve and the worker ran")
        return
    check(w["nodes"] > w["terms"][0].__len__() // 3, "the hierarchy's page holds its tree (%d nodes, %d links)" %
          (w["nodes"], w["links"]))
    rows = read_csv(ref)
    compare(rows, w, [(1, "KE"), (2, "K2E"), (3, "K3E")], 1e-5, "hierarchy")
    compare(rows, w, [(len(w["terms"]) - 1, "L")], 1e-4, "hierarchy")
    kernel_check(src, page, {}, w, "hierarchy")


def punctual_checks(bounce, src, out):
    import punctual_check
    scene, page = os.path.join(out, "lamp.gltf"), os.path.join(out, "lamp.html")
    punctual_check.write(os.path.join(src, "meshes/cornell-box.obj"), scene)
    r = run([bounce, "view", "--live", scene, "--patches", "300", "--ff-visibility", "rays", "-q", "-o", page])
    w1 = worker(src, page, {}) if r.returncode == 0 else None
    w2 = worker(src, page, {"punctual": 2}) if w1 else None
    if not w2:
        check(False, "the punctual page and its worker ran")
        return
    L, ref = w1["terms"][-1], w1["L_solved"]
    top = max(ref)
    worst = max(abs(a - b) / (abs(b) + 1e-3 * top) for a, b in zip(L, ref))
    check(sum(w1["terms"][1]) > 0 and worst < 1e-4, "punctual lights: the page's L is the solve's (worst %.2g)" % worst)
    worst2 = max(abs(a - 2 * b) / (abs(2 * b) + 1e-9) for t1, t2 in zip(w1["terms"], w2["terms"]) for a, b in zip(t2, t1))
    check(worst2 < 1e-9, "punctual lights x2 double every term (worst %.2g)" % worst2)


def budget_and_bad_input(bounce, out, base):
    page = os.path.join(out, "small.html")
    r = run([bounce, "view", "--live"] + base + ["--budget", "0.25", "-o", page])
    ok = r.returncode == 0 and "over the budget" in r.stderr and os.path.exists(page)
    check(ok, "--budget 0.25: built coarser and said so (%s)" % (r.stdout.strip()[-160:]))
    if ok:
        html = open(page).read()
        check("over the budget" in subprocess.run(["node", "-e", "process.stdout.write(Buffer.from(require('fs')"
                                                    ".readFileSync(process.argv[1],'utf8').match(/const LIVE = \"([^\"]*)\"/)[1],"
                                                    "'base64').subarray(12, 4000).toString())", page],
                                                   capture_output=True, text=True).stdout,
              "the coarser page says why in its note")
        check(len(html) < 1.45 * 0.25 * 1048576 + 2.5e6, "the page fits the budget (%d bytes)" % len(html))
    for bad, why in ((["--budget", "0"], "budget"), (["--bounces", "99"], "bounces"), (["-o", os.path.join(out, "x.txt")], "html")):
        dest = os.path.join(out, "bad.html")
        if os.path.exists(dest):
            os.remove(dest)
        r = run([bounce, "view", "--live"] + base + bad + ([] if "-o" in bad else ["-o", dest]))
        check(r.returncode == 2 and why in r.stderr.lower() and not os.path.exists(dest),
              "%s: exit %d, '%s', no page" % (" ".join(bad), r.returncode, r.stderr.strip()[-100:]))


def parse_probe(text):
    """{patch: {term: (r, g, b)}} from the page's probe lines."""
    out = {}
    for ln in text.splitlines():
        parts = ln.split(" | ")
        if len(parts) > 1:
            out[int(parts[0])] = {p.split()[0]: tuple(float(v) for v in p.split()[1:]) for p in parts[1:]}
    return out


def chromium_checks(page, rows, red):
    browser = cdp.find_browser()
    if not browser:
        print("SKIP (the Chromium part): no browser; install Debian's chromium (scripts/setup.sh does)")
        return
    i = red[len(red) // 2]
    url = "file://" + os.path.abspath(page) + "#panel=0&size=800x600&Le.light=34,24,8&rho.red=0.1,0.6,0.1"
    with cdp.Page(browser, url) as p:
        ok = p.wait("window.bnLive && window.bnLive.idle()", timeout=120)
        check(bool(ok), "the live page came up in Chromium")
        if not ok:
            return
        got = parse_probe(p.eval("bnLive.probe([%d])" % i))[i]
        want = tuple(float(rows[i]["KE_" + c]) for c in "RGB")
        err = max(abs(a - b) / abs(b) for a, b in zip(got["KE"], want))
        check(err < 1e-5, "Chromium shows the C solve's KE on red-wall patch %d: %s vs %s (%.2g)" % (i, got["KE"], want, err))
        # the light's EV slider through the DOM: +1 EV doubles KE
        p.eval("(() => { const s = [...document.querySelectorAll('#mats input[type=range]')][0]; s.value = 1;"
               " s.dispatchEvent(new Event('input')); })()")
        p.wait("window.bnLive.idle() && document.getElementById('livetime').textContent.includes('relit')", 60)
        import time
        time.sleep(0.5)
        p.wait("window.bnLive.idle()", 60)
        got2 = parse_probe(p.eval("bnLive.probe([%d])" % i))[i]
        err2 = max(abs(a - 2 * b) / abs(2 * b) for a, b in zip(got2["KE"], got["KE"]))
        check(err2 < 1e-6, "the light's slider at +1 EV doubles the shown KE (%.2g)" % err2)
        t = p.eval("document.getElementById('livetime').textContent")
        check("relit in" in (t or "") and "(WebAssembly)" in t, "the page says what the change cost, in WebAssembly: %s" % t)


def main():
    bounce, src, out = sys.argv[1:4]
    if not shutil.which("node"):
        print("SKIP: no node (Debian's nodejs; scripts/setup.sh installs it)")
        sys.exit(77)
    os.makedirs(out, exist_ok=True)
    base = [os.path.join(src, "meshes/cornell-box.obj"), "--unit", "mm", "--patches", "300", "--ff-visibility", "rays"]
    d = dense_checks(bounce, src, out, base)
    hierarchy_checks(bounce, src, out, base)
    punctual_checks(bounce, src, out)
    budget_and_bad_input(bounce, out, base)
    if d:
        chromium_checks(*d)
    if failures:
        print("%d check(s) failed" % len(failures))
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
