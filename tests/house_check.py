#!/usr/bin/env python3
"""The house's rules, checked on the source tree (issue 39): every function under src/ at most
LIMIT lines, no circle between src/'s files or directories (who calls whom, from the object
files), nothing under src/transport calling into src/formfactor, and no library message (a string outside
src/cli) naming a command-line flag ("--name"), and every warning with its code (bn_warnf).

Functions and messages not yet brought under the rules are listed in KNOWN with their size when
listed: the check fails when a new one appears or a listed one grows, and says so when a listed one
has been fixed (so the list only shrinks). usage: house_check.py SOURCE_DIR OBJECT_DIR (the bounce library's, CMakeFiles/bounce.dir)"""
import glob
import os
import re
import subprocess
import sys

LIMIT = 100

# function -> its length when listed (to be split: issue 39)
KNOWN_LONG = {}

# circles between files (and between src/ directories, "dir NAME") not yet removed, from what each
# object file calls (nm); and calls from src/transport up into src/formfactor
KNOWN_CIRCLES = set()
KNOWN_UPHILL = set()

# library files whose strings still name command-line flags, and how many
KNOWN_FLAGS = {}


def functions(path):
    """(name, first line, length) of each top-level function: a line '{' at column 0 after its
    head, to the next '}' at column 0."""
    lines = open(path, errors="replace").read().split("\n")
    i = 0
    while i < len(lines):
        if lines[i] == "{" and i > 0:
            j = i - 1
            while j > 0 and lines[j][:1] in (" ", "\t"):
                j -= 1
            names = re.findall(r"(\w+)\s*\(", lines[j])
            k = i + 1
            while k < len(lines) and not lines[k].startswith("}"):
                k += 1
            if names:
                yield names[0], j + 1, k - j + 1
            i = k
        i += 1


def check_functions(src, report):
    seen = set()
    for d, _, fs in os.walk(src):
        for f in sorted(fs):
            if not f.endswith((".c", ".cpp", ".h")):
                continue
            p = os.path.join(d, f)
            for name, line, n in functions(p):
                if n <= LIMIT:
                    continue
                seen.add(name)
                where = "%s:%d %s is %d lines" % (os.path.relpath(p, src), line, name, n)
                if name not in KNOWN_LONG:
                    report(False, where + " (at most %d)" % LIMIT)
                elif n > KNOWN_LONG[name]:
                    report(False, where + ", longer than the %d listed" % KNOWN_LONG[name])
    for name in sorted(set(KNOWN_LONG) - seen):
        print("note: %s is now at most %d lines: remove it from KNOWN_LONG" % (name, LIMIT))
    print("functions over %d lines: %d (listed: %d)" % (LIMIT, len(seen), len(KNOWN_LONG)))


def link_graph(objdir, src):
    """file -> the files whose functions it calls, from the library's object files (nm): the true
    dependency between files, whatever header declares what."""
    defs, undef = {}, {}
    base = os.path.join(objdir, "src")
    # only the objects of sources that exist (a moved file's old object may linger in the build)
    objs = sorted(o for o in glob.glob(os.path.join(base, "**", "*.o"), recursive=True)
                  if os.path.exists(os.path.join(src, os.path.relpath(o, base)[:-2])))
    if not objs:
        return {}
    for flag, defined in (("--defined-only", True), ("--undefined-only", False)):
        nm = subprocess.run(["nm", "-A", "-g", flag] + objs, capture_output=True, text=True).stdout
        for line in nm.splitlines():   # "path.o:[address] TYPE symbol"
            m = re.match(r"^(.*?\.o):\s*(?:[0-9a-f]+\s+)?[A-Za-z]\s+(\S+)$", line)
            if not m:
                continue
            name = os.path.relpath(m.group(1), base)[:-2]
            undef.setdefault(name, set())
            if defined:
                defs[m.group(2)] = name
            else:
                undef[name].add(m.group(2))
    graph = {f: {defs[u] for u in us if u in defs and defs[u] != f} for f, us in undef.items()}
    return graph


def circles(graph):
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(tuple(sorted(comp)))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def check_links(objdir, src, report):
    graph = link_graph(objdir, src)
    if not graph:
        report(False, "no object files under %s/src" % objdir)
        return
    dirs = {}
    for f, ts in graph.items():
        for t in ts:
            if f.split("/")[0] != t.split("/")[0]:
                dirs.setdefault(f.split("/")[0], set()).add(t.split("/")[0])
    found = circles(graph) + [tuple(["dir " + d for d in c]) for c in circles(dirs)]
    for c in found:
        if c not in KNOWN_CIRCLES:
            report(False, "a circle between files: " + " <-> ".join(c))
    for c in sorted(KNOWN_CIRCLES - set(found)):
        print("note: the circle %s is gone: remove it from KNOWN_CIRCLES" % " <-> ".join(c))
    for f in sorted(graph):
        for t in sorted(graph[f]):
            if f.startswith("transport/") and t.startswith("formfactor/") and (f, t) not in KNOWN_UPHILL:
                report(False, "%s calls into %s: src/transport sits below src/formfactor" % (f, t))
    print("circles between files and directories: %d (listed: %d)" % (len(found), len(KNOWN_CIRCLES)))


def check_messages(src, report):
    """String literals outside src/cli that name a flag: '--' followed by a letter."""
    count = {}
    for d, _, fs in os.walk(src):
        if os.path.relpath(d, src).split(os.sep)[0] == "cli":
            continue
        for f in sorted(fs):
            if not f.endswith((".c", ".cpp", ".h")):
                continue
            p = os.path.join(d, f)
            rel = os.path.relpath(p, src)
            for ln, line in enumerate(open(p, errors="replace"), 1):
                code = re.sub(r"/\*.*?\*/|//.*$", "", line)
                for lit in re.findall(r'"((?:[^"\\]|\\.)*)"', code):
                    if re.search(r"--[a-z]", lit):
                        count[rel] = count.get(rel, 0) + 1
                        if count[rel] > KNOWN_FLAGS.get(rel, 0):
                            report(False, "%s:%d: a library message names a command-line flag: \"%s\"" % (rel, ln, lit[:60]))
    for rel in sorted(KNOWN_FLAGS):
        if count.get(rel, 0) < KNOWN_FLAGS[rel]:
            print("note: %s names fewer flags (%d) than listed: lower KNOWN_FLAGS" % (rel, count.get(rel, 0)))
    print("library strings naming a flag: %d (listed: %d)" % (sum(count.values()), sum(KNOWN_FLAGS.values())))


def check_warnings(src, report):
    """Every warning carries a code: the library warns through bn_warnf, never bn_logf at BN_LOG_WARN."""
    n = 0
    for p in sorted(glob.glob(os.path.join(src, "**", "*.c*"), recursive=True)):
        text = open(p, errors="replace").read()
        for m in re.finditer(r"bn_logf\([^;]*?BN_LOG_WARN", text):
            report(False, "%s:%d: a warning without a code (bn_logf at BN_LOG_WARN; use bn_warnf)"
                   % (os.path.relpath(p, src), text.count("\n", 0, m.start()) + 1))
        n += len(re.findall(r"\bbn_warnf\(", text))
    print("warnings with a code: %d calls" % n)


def main():
    src = os.path.join(sys.argv[1], "src")
    failures = []

    def report(ok, msg):
        if not ok:
            failures.append(msg)
            print("FAIL " + msg)
    check_functions(src, report)
    check_links(sys.argv[2], src, report)
    check_messages(src, report)
    check_warnings(src, report)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
