# Lights a white diffuse 1 m plane with an equirectangular EXR (Blender's Environment Texture)
# in Cycles and prints, per plane normal, the irradiance E = pi L of its mean radiance L, as one
# line "ROUEN_PLANE <json>" each. Nothing else is in the scene (the camera does not occlude).
# Usage: blender -b --factory-startup --python blender_envmap_plane.py -- SKY.exr OUT_DIR SAMPLES
#        NX,NY,NZ [NX,NY,NZ ...]
import json
import math
import sys

import bpy
from mathutils import Vector

args = sys.argv[sys.argv.index("--") + 1:]
sky, out_dir, samples = args[0], args[1], int(args[2])
normals = [Vector([float(x) for x in a.split(",")]).normalized() for a in args[3:]]

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = 'CYCLES'
scene.cycles.device = 'CPU'
scene.cycles.samples = samples
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.cycles.seed = 1
scene.render.resolution_x = scene.render.resolution_y = 16
scene.render.resolution_percentage = 100
scene.render.film_transparent = False
scene.view_settings.view_transform = 'Standard'
scene.render.image_settings.file_format = 'OPEN_EXR'
scene.render.image_settings.color_depth = '32'

world = bpy.data.worlds.new("rouen")
scene.world = world
world.use_nodes = True
nodes = world.node_tree.nodes
env = nodes.new("ShaderNodeTexEnvironment")
env.image = bpy.data.images.load(sky)
env.image.colorspace_settings.name = 'Linear'
env.interpolation = 'Linear'
env.projection = 'EQUIRECTANGULAR'
world.node_tree.links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
nodes["Background"].inputs["Strength"].default_value = 1.0

material = bpy.data.materials.new("white")
material.use_nodes = True
mnodes = material.node_tree.nodes
for n in list(mnodes):
    if n.type != 'OUTPUT_MATERIAL':
        mnodes.remove(n)
diffuse = mnodes.new("ShaderNodeBsdfDiffuse")
diffuse.inputs["Color"].default_value = (1, 1, 1, 1)
material.node_tree.links.new(diffuse.outputs["BSDF"], mnodes["Material Output"].inputs["Surface"])

bpy.ops.mesh.primitive_plane_add(size=1.0)
plane = bpy.context.active_object
plane.data.materials.append(material)
cam_data = bpy.data.cameras.new("camera")
cam_data.angle = math.radians(8)
camera = bpy.data.objects.new("camera", cam_data)
scene.collection.objects.link(camera)
scene.camera = camera

for i, n in enumerate(normals):
    plane.rotation_mode = 'QUATERNION'
    plane.rotation_quaternion = Vector((0, 0, 1)).rotation_difference(n)
    camera.location = 3 * n
    camera.rotation_mode = 'QUATERNION'
    camera.rotation_quaternion = (-n).to_track_quat('-Z', 'Y' if abs(n.z) > 0.9 else 'Z')
    scene.render.filepath = "%s/plane%d.exr" % (out_dir, i)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath)
    px = list(image.pixels)
    count = len(px) // 4
    mean = [sum(px[c::4]) / count for c in range(3)]
    print("ROUEN_PLANE " + json.dumps({"normal": list(n), "irradiance": [math.pi * m for m in mean]}))
