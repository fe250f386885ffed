#!/usr/bin/env python3
"""The furnace of issue 35's closed-scene check, as an OBJ: a closed 4 x 4 x 4 box (inward) around a unit
icosphere of 20 x 4^LEVELS triangles (outward), as tests/test_hierarchy.c's furnace_make builds in memory.

usage: make_furnace.py LEVELS OUT.obj [lit]
Writes OUT.obj and furnace.mtl beside it. Without `lit`, the white furnace: every face rho 0.9, Le 1
(L = 10 everywhere, every row of F sums to 1). With `lit`, one wall (z = -2) emits Le 1 and every face
has rho 0.5. Run it with `bounce solve OUT.obj --unit m --transport hierarchical --patch-size 0.5`.
"""
import math
import os
import sys

PHI = (1 + 5 ** 0.5) / 2
ICO_V = [(-1, PHI, 0), (1, PHI, 0), (-1, -PHI, 0), (1, -PHI, 0), (0, -1, PHI), (0, 1, PHI),
         (0, -1, -PHI), (0, 1, -PHI), (PHI, 0, -1), (PHI, 0, 1), (-PHI, 0, -1), (-PHI, 0, 1)]
ICO_F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
BOX = [(-2, -2, -2), (2, -2, -2), (2, 2, -2), (-2, 2, -2), (-2, -2, 2), (2, -2, 2), (2, 2, 2), (-2, 2, 2)]
QUADS = [(0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)]


def unit(v):
    n = math.sqrt(sum(x * x for x in v))
    return tuple(x / n for x in v)


def icosphere(levels):
    """Vertices on the unit sphere and outward triangles (counter-clockwise seen from outside)."""
    verts, tris = [unit(v) for v in ICO_V], list(ICO_F)
    for _ in range(levels):
        cache = {}

        def mid(a, b):
            k = (min(a, b), max(a, b))
            if k not in cache:
                verts.append(unit([(verts[a][i] + verts[b][i]) / 2 for i in range(3)]))
                cache[k] = len(verts) - 1
            return cache[k]

        finer = []
        for a, b, c in tris:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            finer += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        tris = finer
    return verts, tris


def main():
    levels, out = int(sys.argv[1]), sys.argv[2]
    lit = len(sys.argv) > 3 and sys.argv[3] == "lit"
    verts, tris = icosphere(levels)
    with open(out, "w") as f:
        f.write("mtllib furnace.mtl\n")
        for v in BOX:
            f.write("v %g %g %g\n" % v)
        for v in verts:
            f.write("v %.17g %.17g %.17g\n" % v)
        for i, q in enumerate(QUADS):   # inward: counter-clockwise seen from inside
            f.write("usemtl %s\n" % ("light" if lit and i == 0 else "grey"))
            f.write("f %d %d %d %d\n" % tuple(x + 1 for x in q))
        f.write("usemtl grey\n")
        for a, b, c in tris:
            f.write("f %d %d %d\n" % (a + 9, b + 9, c + 9))
    with open(os.path.join(os.path.dirname(out), "furnace.mtl"), "w") as f:
        if lit:
            f.write("newmtl grey\nKd 0.5 0.5 0.5\nKe 0 0 0\nnewmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n")
        else:
            f.write("newmtl grey\nKd 0.9 0.9 0.9\nKe 1 1 1\n")


if __name__ == "__main__":
    main()
