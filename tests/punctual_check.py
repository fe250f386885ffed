#!/usr/bin/env python3
"""Punctual lights in a closed room: the Cornell box written as glTF (tests/gltf_tree_check.py's writer,
untransformed), its area light switched off and lit instead by a point light (a bulb below the ceiling)
and a spot shining down beside the tall block; `bounce crosscheck` (the radiosity side's source against
the path tracer's next-event estimation, which share nothing but the scene) must pass, and the log must
say how the lights were read.

usage: punctual_check.py BOUNCE CORNELL.obj OUTDIR
"""
import json
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gltf_tree_check as tree  # noqa: E402
from gltf_check import RAYS, check, failures  # noqa: E402


def write(obj, out):
    tree.ROOM = {"name": "room", "scale": [0.001, 0.001, 0.001]}
    tree.OWN = {}
    tree.write_scene(obj, out)
    gl = json.load(open(out))
    gl["nodes"] = [n for n in gl["nodes"] if n.get("name") != "eye"]
    gl["nodes"][0]["children"] = [c for c in gl["nodes"][0]["children"] if c < len(gl["nodes"])]
    del gl["cameras"]
    for m in gl["materials"]:
        if m["name"] == "light":
            m["emissiveFactor"] = [0, 0, 0]
    gl["extensionsUsed"].append("KHR_lights_punctual")
    gl["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "point", "color": [1, 0.8, 0.6], "intensity": 0.5, "name": "bulb"},
        {"type": "spot", "color": [0.6, 0.8, 1], "intensity": 2, "name": "spot",
         "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}}]}}
    a = -math.pi / 2   # the spot's node turned so that its -z points down
    gl["nodes"] += [{"name": "bulb", "translation": [0.278, 0.45, 0.28], "extensions": {"KHR_lights_punctual": {"light": 0}}},
                    {"name": "spot", "translation": [0.4, 0.5, 0.2], "rotation": [math.sin(a / 2), 0, 0, math.cos(a / 2)],
                     "extensions": {"KHR_lights_punctual": {"light": 1}}}]
    gl["scenes"][0]["nodes"] += [len(gl["nodes"]) - 2, len(gl["nodes"]) - 1]
    json.dump(gl, open(out, "w"))


def main():
    bounce, obj, outdir = sys.argv[1:4]
    os.makedirs(outdir, exist_ok=True)
    scene = os.path.join(outdir, "lamp.gltf")
    write(obj, scene)
    r = subprocess.run([bounce, "crosscheck", scene] + RAYS, capture_output=True, text=True)
    verdict = [ln for ln in r.stdout.splitlines() if ln.startswith("verdict:")]
    print("\n".join(verdict))
    check(r.returncode == 0 and verdict and verdict[0].startswith("verdict: pass"),
          "crosscheck passes with a point and a spot light (exit %d)" % r.returncode)
    check("2 punctual lights" in r.stderr and "W sr^-1" in r.stderr, "the log says how the lights were read")
    print("%d failures" % len(failures))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
