#!/usr/bin/env python3
"""The glTF bake read back by a reader of its own (this file: the GLB container, the JSON and the
accessors by hand, no code shared with bounce's writer), against the same bake written as PLY
through OpenMesh (parsed here too) and against the scene's MTL file.

usage: gltf_check.py BOUNCE SCENE.obj UNIT OUTDIR
Checks, on the element mesh with --per-bounce:
- the .glb container (magic, version, lengths, chunk types, 4-byte alignment);
- positions equal the PLY's (glTF in metres, the PLY in scene units);
- _L and every term (_E, _KE, ..., _REST) equal the PLY's float properties for each vertex;
- the terms sum to _L (E + KE + K2E + K3E + rest = L, float rounding);
- COLOR_0 = min(1, _L x colour_scale) as the asset's extras state;
- each primitive's material carries the MTL's Kd and Ke, and E is nonzero only on emitters;
- the triangles are the PLY's faces fanned (same count, indices in range);
- COLOR_1 .. COLOR_5 = min(1, term x colour_scale) for E .. rest, each named in the extras;
- _FACE_NORMAL: unit, along the normal of one of each vertex's triangles;
and on the input mesh as .gltf + .bin with --ldr: the external buffer, no sRGB-encoded colour set (glTF's
vertex colours are linear: --ldr changes nothing there), fewer vertices than the element mesh, provenance
naming the command;
and against the solve: `bounce solve -n 3` writes every patch's area and terms to a CSV in a run of
its own; a bake with --flat (no vertex shared between patches, so each vertex carries its patch's
value) is grouped into patches by shared vertices here, and every CSV patch must have one group of its
own with the same area (from the glTF's positions) and the same L, E, KE, K2E, K3E.
"""
import json
import os
import struct
import subprocess
import sys
from array import array

COMPONENT = {5126: ("f", 4), 5125: ("I", 4), 5121: ("B", 1), 5123: ("H", 2)}
NCOMP = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}
failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def read_glb(path):
    d = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<III", d, 0)
    check(magic == 0x46546C67, "glb magic")
    check(version == 2, "glb version 2")
    check(length == len(d), "glb length %d == file size %d" % (length, len(d)))
    jlen, jtype = struct.unpack_from("<II", d, 12)
    check(jtype == 0x4E4F534A, "first chunk is JSON")
    check(jlen % 4 == 0, "JSON chunk 4-byte aligned")
    gl = json.loads(d[20:20 + jlen].decode("utf-8"))
    blen, btype = struct.unpack_from("<II", d, 20 + jlen)
    check(btype == 0x004E4942, "second chunk is BIN")
    binary = d[28 + jlen:28 + jlen + blen]
    check(len(binary) == gl["buffers"][0]["byteLength"], "BIN chunk holds the buffer")
    return gl, binary


def read_gltf(path):
    gl = json.load(open(path, encoding="utf-8"))
    uri = gl["buffers"][0]["uri"]
    binary = open(os.path.join(os.path.dirname(path), uri), "rb").read()
    check(len(binary) == gl["buffers"][0]["byteLength"], ".bin length as the JSON says")
    return gl, binary


def accessor(gl, binary, k):
    a = gl["accessors"][k]
    v = gl["bufferViews"][a["bufferView"]]
    code, size = COMPONENT[a["componentType"]]
    n = a["count"] * NCOMP[a["type"]]
    off = v.get("byteOffset", 0) + a.get("byteOffset", 0)
    check(off % 4 == 0, "accessor %d aligned" % k)
    out = array(code)
    out.frombytes(binary[off:off + n * size])
    if sys.byteorder != "little":
        out.byteswap()
    return out, NCOMP[a["type"]]


def read_ply(path):
    d = open(path, "rb").read()
    end = d.index(b"end_header\n") + len(b"end_header\n")
    head = d[:end].decode("ascii").splitlines()
    check("format binary_little_endian 1.0" in head, "PLY is binary little-endian")
    props, nv, nf, elem = [], 0, 0, None
    for ln in head:
        t = ln.split()
        if t[:1] == ["element"]:
            elem = t[1]
            if elem == "vertex":
                nv = int(t[2])
            elif elem == "face":
                nf = int(t[2])
        elif t[:1] == ["property"] and elem == "vertex":
            check(t[1] == "float", "PLY vertex property %s is float" % t[2])
            props.append(t[2])
    rec = 4 * len(props)
    verts = {p: [] for p in props}
    for i in range(nv):
        vals = struct.unpack_from("<%df" % len(props), d, end + i * rec)
        for p, x in zip(props, vals):
            verts[p].append(x)
    off, faces = end + nv * rec, []
    for i in range(nf):
        (k,) = struct.unpack_from("<B", d, off)
        faces.append(struct.unpack_from("<%di" % k, d, off + 1))
        off += 1 + 4 * k
    return verts, faces


def read_mtl(obj):
    lib = None
    for ln in open(obj, encoding="utf-8", errors="replace"):
        t = ln.split()
        if t[:1] == ["mtllib"]:
            lib = os.path.join(os.path.dirname(obj), " ".join(t[1:]))
    mats, cur = {}, None
    for ln in open(lib, encoding="utf-8", errors="replace"):
        t = ln.split()
        if t[:1] == ["newmtl"]:
            cur = t[1]
            mats[cur] = {"Kd": [0.0] * 3, "Ke": [0.0] * 3}
        elif t[:1] in (["Kd"], ["Ke"]) and cur:
            mats[cur][t[0]] = [float(x) for x in t[1:4]]
    return mats


# Form factors with shadow rays for partly occluded pairs: these checks are about the glTF; the exact
# visible parts (the default) are tested in tests/test_ff_visibility.c and would triple the bakes' time.
RAYS = ["--ff-visibility", "rays"]


def close(a, b, rtol, atol=0.0):
    return abs(a - b) <= atol + rtol * max(abs(a), abs(b))


def check_against_solve(bounce, scene, unit, outdir):
    csv, glb = os.path.join(outdir, "solve.csv"), os.path.join(outdir, "flat.glb")
    # shadow rays (RAYS): the glTF is tested here, not the visible parts
    common = [scene, "--unit", unit, "-q", "--patches", "400"] + RAYS
    for cmd in ([bounce, "solve"] + common + ["-n", "3", "-o", csv],
                [bounce, "bake"] + common + ["--per-bounce", "--flat", "-o", glb]):
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            print(r.stderr)
            sys.exit("%s failed (exit %d)" % (" ".join(cmd[:2]), r.returncode))
    r = subprocess.run([bounce, "bake"] + common + ["--flat", "--crease", "10", "-o", glb + ".x.glb"],
                       capture_output=True, text=True)
    check(r.returncode != 0 and "--flat and --crease" in r.stderr and not os.path.exists(glb + ".x.glb"),
          "--flat with --crease is refused (exit %d: %s)" % (r.returncode, r.stderr.strip()))
    rows = [ln.strip().split(",") for ln in open(csv) if not ln.startswith("#")]
    head, rows = rows[0], rows[1:]
    cols = ["area"] + ["%s_%s" % (t, c) for t in ("L", "E", "KE", "K2E", "K3E") for c in "RGB"]
    want = [[float(r[head.index(c)]) for c in cols] for r in rows]
    gl, binary = read_glb(glb)
    attrs = [q for m in gl["meshes"] for q in m["primitives"]][0]["attributes"]
    pos, _ = accessor(gl, binary, attrs["POSITION"])
    terms = [accessor(gl, binary, attrs[n])[0] for n in ("_L", "_E", "_KE", "_K2E", "_K3E")]
    nv = len(pos) // 3
    parent = list(range(nv))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    tris = []
    for p in [q for m in gl["meshes"] for q in m["primitives"]]:
        idx, _ = accessor(gl, binary, p["indices"])
        for t in range(0, len(idx), 3):
            a, b, c = idx[t:t + 3]
            tris.append((a, b, c))
            parent[find(b)] = find(a)
            parent[find(c)] = find(a)
    groups = {}
    for a, b, c in tris:
        u = [pos[3 * b + k] - pos[3 * a + k] for k in range(3)]
        v = [pos[3 * c + k] - pos[3 * a + k] for k in range(3)]
        cr = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
        g = groups.setdefault(find(a), [0.0, set()])
        g[0] += 0.5 * (cr[0] ** 2 + cr[1] ** 2 + cr[2] ** 2) ** 0.5
        g[1].update((a, b, c))
    got, spread = [], 0.0
    for area, vs in groups.values():
        vals = [[t[3 * i + c] for t in terms for c in range(3)] for i in vs]
        spread = max(spread, max(abs(x - y) for vv in vals for x, y in zip(vv, vals[0])))
        got.append([area] + vals[0])
    check(spread == 0.0, "--flat: every vertex of a patch carries the same values (largest spread %g)" % spread)
    check(len(got) == len(want), "--flat bake: %d patches, the solve's CSV %d" % (len(got), len(want)))

    def diff(a, b):   # relative for the area, relative above 1e-6 W m^-2 sr^-1 for the radiances
        return max([abs(a[0] - b[0]) / b[0]] + [abs(x - y) / max(abs(y), 1e-6) for x, y in zip(a[1:], b[1:])])

    unused, worst = list(range(len(got))), 0.0
    for w in want:   # each patch of the solve, its own group of the bake
        j = min(unused, key=lambda k: diff(got[k], w)) if unused else None
        if j is None:
            break
        worst = max(worst, diff(got[j], w))
        unused.remove(j)
    check(worst < 1e-5, "each of the solve's %d patches matches a patch of the bake: area, L and every term "
          "(worst relative %.2e; float storage)" % (len(want), worst))
    print("against the solve: %d patches, worst relative difference %.2e" % (len(want), worst))


def triangles(gl, binary, pos, prims):
    """Each triangle of the primitives: its three vertex indices and its (unnormalised) normal, the cross
    product of its edges."""
    for p in prims:
        idx, _ = accessor(gl, binary, p["indices"])
        for t in range(0, len(idx), 3):
            a, b, c = idx[t:t + 3]
            u = [pos[3 * b + k] - pos[3 * a + k] for k in range(3)]
            v = [pos[3 * c + k] - pos[3 * a + k] for k in range(3)]
            yield (a, b, c), [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def check_face_normals(gl, binary, attrs, pos, prims):
    """_FACE_NORMAL: each vertex's is a unit vector along the normal of one of its triangles (the face its
    values were gathered on)."""
    check("_FACE_NORMAL" in attrs, "_FACE_NORMAL present in a per-bounce bake")
    if "_FACE_NORMAL" not in attrs:
        return
    fn, _ = accessor(gl, binary, attrs["_FACE_NORMAL"])
    best = [-2.0] * (len(pos) // 3)
    for tri, n in triangles(gl, binary, pos, prims):
        ln = sum(x * x for x in n) ** 0.5
        if ln > 0:
            for q in tri:
                best[q] = max(best[q], sum(fn[3 * q + k] * n[k] for k in range(3)) / ln)
    used = [x for x in best if x > -2]
    worst_len = max(abs(sum(fn[3 * i + k] ** 2 for k in range(3)) - 1) for i in range(len(best)))
    check(worst_len < 1e-5 and min(used) > 1 - 1e-4, "_FACE_NORMAL: unit (worst %.1e) and along one of each vertex's "
          "triangles' normals (worst cosine %.6f)" % (worst_len, min(used)))


def main():
    bounce, scene, unit, outdir = sys.argv[1:5]
    scale_m = {"m": 1.0, "cm": 0.01, "mm": 0.001}[unit]
    os.makedirs(outdir, exist_ok=True)
    glb, ply, gltf = (os.path.join(outdir, n) for n in ("bake.glb", "bake.ply", "input.gltf"))
    base = [bounce, "bake", scene, "--unit", unit, "-q", "--patches", "400"] + RAYS
    for extra in (["--per-bounce", "-o", glb], ["--per-bounce", "-o", ply],
                  ["--mesh", "input", "--ldr", "-o", gltf]):
        r = subprocess.run(base + extra, capture_output=True, text=True)
        if r.returncode != 0:
            print(r.stderr)
            sys.exit("bounce bake %s failed (exit %d)" % (" ".join(extra), r.returncode))

    gl, binary = read_glb(glb)
    verts, faces = read_ply(ply)
    prim = [q for m in gl["meshes"] for q in m["primitives"]]
    attrs = prim[0]["attributes"]
    for p in prim:
        check(p["attributes"] == attrs, "every primitive shares the vertex attributes")
    names = ["_L", "_E", "_KE", "_K2E", "_K3E", "_REST"]
    for n in ["POSITION", "COLOR_0"] + names:
        check(n in attrs, "attribute %s present" % n)
    pos, _ = accessor(gl, binary, attrs["POSITION"])
    nv = len(pos) // 3
    check(nv == len(verts["x"]), "vertex count %d == PLY's %d" % (nv, len(verts["x"])))
    worst_pos = 0.0
    for i in range(nv):
        for c, ax in enumerate("xyz"):
            worst_pos = max(worst_pos, abs(pos[3 * i + c] / scale_m - verts[ax][i]) / max(1.0, abs(verts[ax][i])))
    check(worst_pos < 1e-6, "positions equal the PLY's (worst relative %.2e)" % worst_pos)
    ply_name = {"_L": ("red", "green", "blue")}
    for n, pn in (("_E", "E"), ("_KE", "KE"), ("_K2E", "K2E"), ("_K3E", "K3E"), ("_REST", "rest")):
        ply_name[n] = tuple("%s_%s" % (pn, c) for c in ("red", "green", "blue"))
    vals = {}
    for n in names:
        vals[n], _ = accessor(gl, binary, attrs[n])
        bad = sum(1 for i in range(nv) for c in range(3) if vals[n][3 * i + c] != verts[ply_name[n][c]][i])
        check(bad == 0, "%s equals the PLY's %s on every vertex (%d differ)" % (n, ply_name[n][0], bad))
    worst_sum = 0.0
    for k in range(3 * nv):
        s = sum(vals[n][k] for n in names[1:])
        worst_sum = max(worst_sum, abs(s - vals["_L"][k]) / max(vals["_L"][k], 1e-3))
    check(worst_sum < 1e-5, "E + KE + K2E + K3E + rest = L (worst %.2e)" % worst_sum)
    extras = gl["asset"]["extras"]
    cs = extras["colour_scale"]
    col0, _ = accessor(gl, binary, attrs["COLOR_0"])
    worst_c0 = max(abs(col0[k] - min(1.0, vals["_L"][k] * cs)) for k in range(3 * nv))
    check(worst_c0 < 1e-6, "COLOR_0 = min(1, L x colour_scale %.4g) (worst %.2e)" % (cs, worst_c0))
    check(0 <= min(col0) and max(col0) <= 1, "COLOR_0 in [0, 1]")
    for k, n in enumerate(names[1:], start=1):   # COLOR_1 .. : the terms as COLOR_0 shows L, linear
        ck, _ = accessor(gl, binary, attrs["COLOR_%d" % k])
        worst = max(abs(ck[i] - min(1.0, vals[n][i] * cs)) for i in range(3 * nv))
        check(worst < 1e-6 and extras["attributes"].get("COLOR_%d" % k) == n[1:].replace("REST", "rest"),
              "COLOR_%d = min(1, %s x colour_scale), named in the extras (worst %.2e)" % (k, n, worst))
    mtl = read_mtl(scene)
    emitters = set()
    ntri = 0
    for p in prim:
        m = gl["materials"][p["material"]]
        want = mtl[m["name"]]
        check(all(close(a, b, 1e-7) for a, b in zip(m["extras"]["reflectance"], want["Kd"])),
              "material %s reflectance = MTL Kd" % m["name"])
        check(all(close(a, b, 1e-7) for a, b in zip(m["extras"]["emitted_radiance"], want["Ke"])),
              "material %s emitted radiance = MTL Ke" % m["name"])
        check("KHR_materials_unlit" in m.get("extensions", {}), "material %s is unlit" % m["name"])
        idx, _ = accessor(gl, binary, p["indices"])
        check(len(idx) % 3 == 0 and max(idx) < nv, "primitive indices are triangles in range")
        ntri += len(idx) // 3
        if max(want["Ke"]) > 0:
            emitters.update(idx)
    check(ntri == sum(len(f) - 2 for f in faces), "triangles %d == the PLY's faces fanned" % ntri)
    check_face_normals(gl, binary, attrs, pos, prim)
    lit = {i for i in range(nv) if max(vals["_E"][3 * i:3 * i + 3]) > 0}
    check(lit and lit <= emitters, "E is nonzero on %d vertices, all of emitters" % len(lit))
    check("bake" in extras["provenance"].get("command line", ""), "provenance records the command line")

    gi, bi = read_gltf(gltf)
    pa = [q for m in gi["meshes"] for q in m["primitives"]][0]["attributes"]
    check("COLOR_1" not in pa and "_L" in pa and "_E" not in pa,
          ".gltf with --ldr: COLOR_0 and _L, no sRGB-encoded set (glTF's colours are linear), no terms")
    c0 = gi["accessors"][pa["COLOR_0"]]
    check(c0["componentType"] == 5126, "COLOR_0 is float (linear)")
    n_in = gi["accessors"][pa["POSITION"]]["count"]
    check(0 < n_in < nv, "input mesh: %d vertices, fewer than the element mesh's %d" % (n_in, nv))

    check_against_solve(bounce, scene, unit, outdir)

    print("glTF read back: %d vertices, %d triangles, %d primitives; colour scale %.4g; %d failures"
          % (nv, ntri, len(prim), cs, len(failures)))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
