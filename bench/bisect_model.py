#!/usr/bin/env python3
"""Cut every triangle of a model-box scene's model in two (bench/ --big: the bunny cut 2x).

usage: bisect_model.py IN.obj OUT.obj
IN.obj is what ../shared/data/scenes/make-model-box.py writes (the box, then `o model` with
absolute indices). Each model triangle is split at the midpoint of its longest edge into two
triangles of the same winding: the surface is unchanged and the polygon count doubles. A
neighbour that shares that edge is not split there (a T-junction: the midpoint lies on its edge,
so no crack opens; bounce's contacts and the hierarchy take such meshes as scans have them).
The .mtl beside IN.obj is copied beside OUT.obj.
"""
import shutil
import sys


def main():
    src, out = sys.argv[1:3]
    lines = open(src, encoding="utf-8").read().splitlines()
    verts, head, faces, in_model = [], [], [], False
    for ln in lines:
        if ln.startswith("v "):
            verts.append([float(x) for x in ln.split()[1:4]])
        if ln.startswith("o "):
            in_model = ln.split()[1] == "model"
        if in_model and ln.startswith("f "):
            faces.append([int(w.split("/")[0]) for w in ln.split()[1:]])
        else:
            head.append(ln)
    new_v, new_f = [], []
    for f in faces:
        if len(f) != 3:
            new_f.append(f)
            continue
        p = [verts[i - 1] for i in f]
        d = [sum((p[(k + 1) % 3][c] - p[k][c]) ** 2 for c in range(3)) for k in range(3)]
        k = d.index(max(d))   # the edge f[k] -> f[k + 1]
        a, b, c = f[k], f[(k + 1) % 3], f[(k + 2) % 3]
        new_v.append([(verts[a - 1][i] + verts[b - 1][i]) / 2 for i in range(3)])
        m = len(verts) + len(new_v)
        new_f += [[a, m, c], [m, b, c]]
    with open(out + ".tmp", "w", encoding="utf-8", newline="\n") as w:
        w.write("# %s with each model triangle cut in two at its longest edge (bench/bisect_model.py)\n" % src.rsplit("/", 1)[-1])
        for ln in head:
            if ln.startswith("mtllib"):
                ln = "mtllib " + out.rsplit("/", 1)[-1].replace(".obj", ".mtl")
            w.write(ln + "\n")
        for v in new_v:
            w.write("v %.6f %.6f %.6f\n" % tuple(v))
        for f in new_f:
            w.write("f " + " ".join(str(i) for i in f) + "\n")
    shutil.move(out + ".tmp", out)
    shutil.copyfile(src.replace(".obj", ".mtl"), out.replace(".obj", ".mtl"))


main()
