# Makes meshes/cornell-box-blender.glb: meshes/cornell-box.obj through Blender's own OBJ importer and
# glTF exporter (Debian's Blender 3.4), a real exporter's file for the glTF reader's tests and manual.
# The OBJ is in millimetres, glTF in metres: the objects are scaled by 1/1000 before export. Blender
# marks every material doubleSided (its "Backface Culling" is off by default) and writes the light's
# Le 17 12 4 as emissiveFactor (1, 0.706, 0.235) x KHR_materials_emissive_strength 17.
# usage: blender -b --python scripts/cornell_box_to_glb.py -- OUT.glb   (from the repository's root)
import sys

import bpy

out = sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else "meshes/cornell-box-blender.glb"
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.obj(filepath="meshes/cornell-box.obj", axis_forward='-Z', axis_up='Y')
for o in bpy.context.scene.objects:
    o.scale = (0.001, 0.001, 0.001)
bpy.ops.object.select_all(action='SELECT')
bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB')
