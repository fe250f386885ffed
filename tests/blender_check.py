#!/usr/bin/env python3
"""A per-bounce glTF bake as Blender 3.4 imports it (headless, Debian's Blender, with the documented
workaround import_shading='FLAT'): every colour set arrives, named by the mesh's custom properties, with
the bake's own values.

usage: blender_check.py BOUNCE CORNELL.obj OUTDIR
The bake (`bounce bake --per-bounce --for blender`) is read by hand here (tests/gltf_check.py's reader):
COLOR_0 must be min(1, _L x colour_scale) and COLOR_k min(1, term x colour_scale). Blender then imports
it; for each mesh object it reports its colour attributes and, per face corner, the corner's position
and colours. Checked: the attributes are Col, Col.001, ... one per colour set; the mesh's custom
properties name them (COLOR_0 = L, COLOR_1 = E, ...); every corner's colour in each attribute is, within
Blender's 8-bit sRGB storage, the colour the glTF gives a vertex at that place in that set. Skipped (77)
where Blender is not installed (scripts/setup.sh does not install it: 600 MB).
"""
import json
import os
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gltf_check import RAYS, accessor, check, failures, read_glb  # noqa: E402

DUMP = r"""
import bpy, json, sys
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=sys.argv[-2], import_shading='FLAT')
out = []
for o in bpy.data.objects:
    if o.type != 'MESH':
        continue
    me, mw = o.data, o.matrix_world
    cols = [a.name for a in me.color_attributes]
    corners = []
    for loop in me.loops:
        p = mw @ me.vertices[loop.vertex_index].co
        corners.append([list(p)] + [list(me.color_attributes[c].data[loop.index].color_srgb[:3]) for c in cols])
    out.append({"name": o.name, "colours": cols, "props": {k: me[k] for k in me.keys() if k.startswith("COLOR_")},
                "corners": corners})
json.dump(out, open(sys.argv[-1], "w"))
"""


def srgb(x):
    x = min(1.0, max(0.0, x))
    return 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055


def bake_sets(glb):
    """Per vertex position (metres, Blender's axes: x, -z, y): the list of colour tuples of each set."""
    gl, binary = read_glb(glb)
    prim = gl["meshes"][0]["primitives"][0]["attributes"]
    pos, _ = accessor(gl, binary, prim["POSITION"])
    names = ["COLOR_%d" % k for k in range(10) if "COLOR_%d" % k in prim]
    sets = [accessor(gl, binary, prim[n])[0] for n in names]
    scale = gl["asset"]["extras"]["colour_scale"]
    radiance = [accessor(gl, binary, prim["_" + t.upper()])[0] for t in ["L", "E", "KE", "K2E", "K3E", "REST"]]
    worst = max(abs(c[i] - min(1.0, r[i] * scale)) for c, r in zip(sets, radiance) for i in range(len(c)))
    check(worst < 1e-6, "COLOR_k = min(1, term x colour_scale) for L, E, KE, K2E, K3E, rest (worst %.1e)" % worst)
    where = {}
    for v in range(len(pos) // 3):
        key = (round(pos[3 * v], 4), round(-pos[3 * v + 2], 4), round(pos[3 * v + 1], 4))
        where.setdefault(key, []).append([srgb(s[3 * v + c]) for s in sets for c in range(3)])
    return gl, names, where


def main():
    bounce, obj, outdir = sys.argv[1:4]
    blender = shutil.which("blender")
    if not blender:
        print("SKIP: no blender (apt-get install blender: Debian's 3.4, the version this checks)")
        sys.exit(77)
    os.makedirs(outdir, exist_ok=True)
    glb, dump, script = (os.path.join(outdir, n) for n in ("bake.glb", "blender.json", "dump.py"))
    r = subprocess.run([bounce, "bake", obj, "--unit", "mm", "-q", "--patches", "200", "--per-bounce", "--for",
                        "blender", "-o", glb] + RAYS, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("bake failed: %s" % r.stderr)
    gl, names, where = bake_sets(glb)
    open(script, "w").write(DUMP)
    # Blender's Python finds its modules (numpy) from the python3 on PATH: not a pyenv's or a venv's
    own = os.path.dirname(sys.executable)
    path = [p for p in os.environ.get("PATH", "").split(":") if p != own and "pyenv" not in p]
    env = dict(os.environ, PATH=":".join(path))
    r = subprocess.run([blender, "-b", "--python", script, "--", glb, dump], capture_output=True, text=True,
                       timeout=300, env=env)
    if r.returncode != 0 or not os.path.exists(dump):
        print(r.stdout[-2000:], r.stderr[-2000:])
        sys.exit("blender failed (exit %d)" % r.returncode)
    objs = json.load(open(dump))
    want_cols = ["Col"] + ["Col.%03d" % k for k in range(1, len(names))]
    terms = ["L", "E", "KE", "K2E", "K3E", "rest"]
    worst, corners = 0.0, 0
    for o in objs:
        check(o["colours"] == want_cols, "%s: colour attributes %s" % (o["name"], o["colours"]))
        check([o["props"].get("COLOR_%d" % k) for k in range(len(names))] == terms,
              "%s: custom properties name the sets %s" % (o["name"], o["props"]))
        for c in o["corners"]:
            key = tuple(round(x, 4) for x in c[0])
            got = [x for col in c[1:] for x in col]
            cands = where.get(key, [])
            corners += 1
            err = min((max(abs(a - b) for a, b in zip(got, w)) for w in cands), default=1.0)
            worst = max(worst, err)
    check(corners > 0 and worst <= 1.5 / 255, "every corner of %d in Blender has the bake's colours in every set "
          "(worst sRGB difference %.4f, 8-bit storage: 1/255 = 0.0039)" % (corners, worst))
    print("Blender: %d objects, %d corners, %d colour sets, worst sRGB difference %.4f; %d failures"
          % (len(objs), corners, len(names), worst, len(failures)))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
