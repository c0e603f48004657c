# Imports a binary glTF into an empty Blender scene and prints what came in as one line,
# "ROUEN_GLTF <json>": the mesh objects' names, their world-space bounds (Blender's z up), the
# materials and whether each has an image texture on its base colour.
# Usage: blender -b --factory-startup --python blender_gltf_import.py -- FILE.glb
import json
import sys

import bpy
import numpy

# Debian 12's Blender 3.4 glTF importer uses numpy.bool, which its numpy (1.24) no longer has
# (AttributeError in set_poly_smoothing): give it back the builtin it aliased.
if "bool" not in numpy.__dict__:
    numpy.bool = bool

path = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
meshes = [o for o in bpy.context.scene.objects if o.type == 'MESH']
lo = [float('inf')] * 3
hi = [float('-inf')] * 3
triangles = 0
for o in meshes:
    for v in o.data.vertices:
        w = o.matrix_world @ v.co
        for i in range(3):
            lo[i] = min(lo[i], w[i])
            hi[i] = max(hi[i], w[i])
    o.data.calc_loop_triangles()
    triangles += len(o.data.loop_triangles)
materials = {}
for m in bpy.data.materials:
    if not m.use_nodes:
        continue
    textured = False
    for node in m.node_tree.nodes:
        if node.type == 'BSDF_PRINCIPLED':
            for link in node.inputs['Base Color'].links:
                textured = textured or link.from_node.type == 'TEX_IMAGE'
    materials[m.name] = textured
images = [i.name for i in bpy.data.images if i.size[0] > 0]
print("ROUEN_GLTF " + json.dumps({"meshes": sorted(o.name for o in meshes), "min": lo, "max": hi,
                                  "triangles": triangles, "materials": materials,
                                  "images": len(images)}))
