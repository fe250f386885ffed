#!/usr/bin/env python3
"""The manual's links, the README's cheap tour lines and the manual's examples. Every relative link
in README.md and doc/*.md names a file that exists; the README's five-minute tour runs its `info`
and `solve` lines as written (with B and S as the tour sets them; the other lines are each a
command other tests run at length); every ```sh block of doc/*.md runs as written, as doctests do,
from a scratch directory holding the repository's meshes/ with `bounce` on PATH, and must exit 0
(a block fenced ```sh no-test is a long one, said and skipped; one with mpirun needs mpirun).
usage: docs_check.py SOURCE_DIR BOUNCE"""
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

src, exe = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
fails = 0
pages = [os.path.join(src, "README.md")] + sorted(glob.glob(os.path.join(src, "doc", "*.md")))
links = 0
for page in pages:
    text = open(page).read()
    for m in re.finditer(r"\]\(([^)\s]+)\)", text):
        url = m.group(1).split("#")[0]
        if not url or re.match(r"^[a-z]+:", url):
            continue
        links += 1
        target = os.path.normpath(os.path.join(os.path.dirname(page), url))
        if not os.path.exists(target):
            print("FAIL %s: link to %s: no such file" % (os.path.relpath(page, src), url))
            fails += 1
print("links checked: %d in %d pages" % (links, len(pages)))

readme = open(os.path.join(src, "README.md")).read()
tour = re.search(r"## A five-minute tour\s+```sh\n(.*?)```", readme, re.S)
if not tour:
    print("FAIL README.md: no five-minute tour block")
    sys.exit(1)
lines = [l.split("#")[0].strip() for l in tour.group(1).splitlines()]
cheap = [l for l in lines if l.startswith("$B info") or l.startswith("$B solve")]
if len(cheap) < 2:
    print("FAIL README.md: the tour has no info and solve lines")
    fails += 1
with tempfile.TemporaryDirectory() as work:
    env = dict(os.environ, B=exe, S=os.path.join(src, "meshes", "cornell-box.obj"))
    os.symlink(os.path.join(src, "meshes"), os.path.join(work, "meshes"))   # the tour runs from the repository
    for l in cheap:
        r = subprocess.run(["bash", "-c", l], cwd=work, env=env, capture_output=True, text=True)
        print("%s %s (exit %d)" % ("ok  " if r.returncode == 0 else "FAIL", l, r.returncode))
        fails += r.returncode != 0
    if os.path.exists(os.path.join(work, "patches.csv")):
        rows = [x for x in open(os.path.join(work, "patches.csv")) if not x.startswith("#")]
        header = rows[0].split(",")
        ok = all(k in header for k in ("L_R", "E_R", "KE_R", "K2E_R", "K3E_R")) and len(rows) > 100
        print("%s patches.csv has L, E, KE, K2E, K3E and %d patches" % ("ok  " if ok else "FAIL", len(rows) - 1))
        fails += not ok

def run_examples(src, exe):
    """Each page's ```sh blocks, in order, in one scratch directory per page."""
    bad = ran = 0
    with tempfile.TemporaryDirectory() as work:
        os.mkdir(os.path.join(work, "bin"))
        os.symlink(exe, os.path.join(work, "bin", "bounce"))
        env = dict(os.environ, PATH=os.path.join(work, "bin") + os.pathsep + os.environ.get("PATH", ""),
                   OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
        for page in sorted(glob.glob(os.path.join(src, "doc", "*.md"))):
            name = os.path.relpath(page, src)
            here = os.path.join(work, os.path.basename(page)[:-3])
            os.mkdir(here)
            os.symlink(os.path.join(src, "meshes"), os.path.join(here, "meshes"))
            for m in re.finditer(r"^```sh([^\n]*)\n(.*?)^```", open(page).read(), re.M | re.S):
                block, tags = m.group(2), m.group(1).split()
                first = block.strip().splitlines()[0] if block.strip() else ""
                if "no-test" in tags:
                    print("skip %s: %s (fenced no-test: a long run)" % (name, first))
                    continue
                if "mpirun" in block and not shutil.which("mpirun"):
                    print("skip %s: %s (no mpirun here)" % (name, first))
                    continue
                t0 = time.monotonic()
                r = subprocess.run(["bash", "-e", "-c", block], cwd=here, env=env, capture_output=True, text=True)
                ran += 1
                print("%s %s: %s (exit %d, %.1f s)" % ("ok  " if r.returncode == 0 else "FAIL", name, first, r.returncode,
                                                      time.monotonic() - t0))
                if r.returncode != 0:
                    bad += 1
                    print(r.stdout[-2000:] + r.stderr[-2000:])
    print("examples run: %d, failed: %d" % (ran, bad))
    return bad


fails += run_examples(src, exe)
sys.exit(1 if fails else 0)
