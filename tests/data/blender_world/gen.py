# An independent validation world for rouen, built from code and rendered by Blender/Cycles.
#
#   blender -b --factory-startup --python gen.py -- --out DIR [--rouen PATH] [--scale S]
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH --sky-pano-float
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH --ground-patch
#
# --sky-pano-float renders only the mast sky panorama of each slot again, with the camera,
# settings and seed of t<k>_sky_pano.exr (samples x --scale), as float32 (PXR24: 24-bit float)
# in t<k>_sky_pano_f32.exr, where the sun disc (~2e6) is not clipped at half float's 65504. It
# writes nothing else (no building.obj, list.txt, cameras.json, truth.json or checks.json).
# sky_f32/ holds them at --scale 16 (README.md says why).
#
# --ground-patch gives the ground two albedos: a bright matte patch north of the building
# (GROUND_PATCH: x -20..30 m, y 4..40 m), whose part just north of the building the ground
# panorama (south-west of the tower) cannot see past the tower and annex, and the rest of the
# 4 x 4 km plane as before. The plane is then cut into a 3 x 3 grid of coplanar quads sharing
# their vertices (no overlapping faces, no T-junctions), the centre quad the patch. Everything
# else is as without it; truth.json records the patch. ../blender_ground/ was rendered with it.
#
# A campanile (a 6 x 6 x 24 m tower with a pyramid roof and a 12 x 8 x 7 m annex) on a large
# ground plane with a wall, two boxes and two trees around it, lit by Cycles' Nishita sky
# texture with its sun disc (the only light), at five times of one day. The sun's position
# for each time is asked of `rouen sun`, so the world and rouen agree on the ephemeris.
# Writes into DIR: the renders (OpenEXR, linear scene radiance), building.obj (the building
# only, one OBJ group per block, in rouen's east-north-up frame), list.txt and cameras.json
# for `rouen import`, truth.json (albedos, site, times, sun positions, cameras) and
# checks.json (the projection and sun-position checks made here).
#
# Frames: Blender's world frame is rouen's: x east, y north, z up, metres. A rouen camera
# (x right, y down, z forward) is Blender's camera rotated by diag(1, -1, -1) for a pinhole
# (Blender looks down its -z with +y up) and by diag(-1, -1, 1) for Cycles' equirectangular
# panorama (its image centre is the camera's -z, so rouen's column 0 is the camera's +z).
# Nishita's sun_rotation is the compass azimuth (from north through east) in radians.
import argparse
import json
import math
import os
import subprocess
import sys
import time

import bpy
import mathutils
import numpy as np

SITE = {"lat_deg": 45.0, "lon_deg": 7.0, "height_m": 300.0}
DATE = "2026-09-08"
ZONE = "+02:00"  # CEST, the local time of the slots
# (local time, UTC time): four training times and one held-out low-sun time (last).
TIMES = [
    ("09:00", "07:00"),
    ("11:30", "09:30"),
    ("14:00", "12:00"),
    ("16:30", "14:30"),
    ("18:15", "16:15"),
]
HELDOUT = 4
SUN_DIAMETER_DEG = 0.545  # Nishita sun disc (the real sun's mean angular diameter)

# Materials (Principled BSDF, base colour linear). Matte: roughness 1, specular 0.
MATTE = {"roughness": 1.0, "specular": 0.0}
GLOSSY = {"roughness": 0.35, "specular": 0.5}
BLOCK_MATERIALS = {
    "tower": {"base_color": [0.62, 0.50, 0.38], **MATTE},
    "roof": {"base_color": [0.45, 0.20, 0.13], **GLOSSY},
    "annex": {"base_color": [0.36, 0.42, 0.50], **MATTE},
}
SURROUNDING_MATERIALS = {
    "ground": {"base_color": [0.26, 0.23, 0.19], **MATTE},
    "wall": {"base_color": [0.55, 0.53, 0.50], **MATTE},
    "shed": {"base_color": [0.40, 0.22, 0.15], **MATTE},
    "car": {"base_color": [0.12, 0.20, 0.40], **MATTE},
    "crown": {"base_color": [0.10, 0.22, 0.07], **MATTE},
    "trunk": {"base_color": [0.25, 0.17, 0.10], **MATTE},
}
# --ground-patch: the ground's second albedo, on the rectangle x0, x1, y0, y1 (m) at z = 0.
GROUND_PATCH = {"rect": [-20.0, 30.0, 4.0, 40.0], "base_color": [0.60, 0.55, 0.48], **MATTE}

# Cameras. Architecture views: (name, azimuth of the eye from the aim point, distance m,
# eye height m, aim point). Pinhole, no distortion.
ARCH_SIZE = (480, 360)
ARCH_HFOV_DEG = 60.0
ARCH_VIEWS = [
    ("arch0", 200.0, 40.0, 1.7, (3.0, 0.0, 11.0)),
    ("arch1", 120.0, 40.0, 4.0, (4.0, 0.0, 10.0)),
    ("arch2", 315.0, 38.0, 8.0, (3.0, 0.0, 14.0)),
]
PANO_SIZE = (512, 256)
GROUND_PANO_EYE = (-8.0, -10.0, 1.7)  # beside the building, south-west of the tower
MAST_EYE = (0.0, 0.0, 29.5)  # 1.5 m above the roof's apex: sky panorama and sun camera
SUN_SIZE = (160, 160)
SUN_HFOV_DEG = 4.0

# Cycles samples per pixel at --scale 1.
SAMPLES = {"arch": 512, "ground_pano": 256, "sky_pano": 64, "sun": 32}


# ---------------------------------------------------------------------------------------------
# Geometry (ENU metres). Polygons are counter-clockwise seen from outside (rouen's OBJ rule).


def box_polygons(x0, x1, y0, y1, z0, z1, bottom=False):
    p = [
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],  # south
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],  # east
        [(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)],  # north
        [(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)],  # west
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],  # top
    ]
    if bottom:
        p.append([(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)])
    return p


def building_blocks():
    """The building: {block: [polygon, ...]}. No bottom faces (they stand on the ground);
    the faces the tower and the annex share are left out."""
    h, apex = 24.0, 28.0
    x0, x1, y0, y1 = -3.0, 3.0, -3.0, 3.0
    tower = [
        [(x0, y0, 0), (x1, y0, 0), (x1, y0, h), (x0, y0, h)],  # south
        [(x1, y0, 7), (x1, y1, 7), (x1, y1, h), (x1, y0, h)],  # east, above the annex
        [(x1, y1, 0), (x0, y1, 0), (x0, y1, h), (x1, y1, h)],  # north
        [(x0, y1, 0), (x0, y0, 0), (x0, y0, h), (x0, y1, h)],  # west
    ]
    top = (0.0, 0.0, apex)
    roof = [
        [(x0, y0, h), (x1, y0, h), top],
        [(x1, y0, h), (x1, y1, h), top],
        [(x1, y1, h), (x0, y1, h), top],
        [(x0, y1, h), (x0, y0, h), top],
    ]
    a0, a1, b0, b1, ah = 3.0, 15.0, -4.0, 4.0, 7.0
    annex = [
        [(a0, b0, 0), (a1, b0, 0), (a1, b0, ah), (a0, b0, ah)],  # south
        [(a1, b0, 0), (a1, b1, 0), (a1, b1, ah), (a1, b0, ah)],  # east
        [(a1, b1, 0), (a0, b1, 0), (a0, b1, ah), (a1, b1, ah)],  # north
        [(a0, b1, 0), (a0, y1, 0), (a0, y1, ah), (a0, b1, ah)],  # west, north of the tower
        [(a0, y0, 0), (a0, b0, 0), (a0, b0, ah), (a0, y0, ah)],  # west, south of the tower
        [(a0, b0, ah), (a1, b0, ah), (a1, b1, ah), (a0, b1, ah)],  # flat roof
    ]
    return {"tower": tower, "roof": roof, "annex": annex}


def polygon_normal(poly):
    p = [np.array(v, float) for v in poly]
    n = np.cross(p[1] - p[0], p[2] - p[0])
    return n / np.linalg.norm(n)


def check_polygons_outward(blocks, centre):
    """Every polygon's normal points away from the building (counter-clockwise from outside)."""
    for name, polys in blocks.items():
        for poly in polys:
            c = np.mean(np.array(poly, float), axis=0)
            n = polygon_normal(poly)
            if name == "annex":
                inside = np.array([9.0, 0.0, 3.5])
            else:
                inside = np.array(centre)
            if np.dot(n, c - inside) <= 0:
                raise RuntimeError(f"block {name}: polygon {poly} faces inwards")


def write_obj(path, blocks):
    lines = [
        "# rouen validation world (Blender/Cycles): the building only, generated by gen.py",
        "# east-north-up metres (x east, y north, z up); faces counter-clockwise from outside",
    ]
    vid = 0
    for name, polys in blocks.items():
        lines.append(f"g {name}")
        for poly in polys:
            for v in poly:
                lines.append("v %.4f %.4f %.4f" % tuple(v))
            idx = " ".join(str(vid + k + 1) for k in range(len(poly)))
            lines.append(f"f {idx}")
            vid += len(poly)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def triangles(blocks):
    """Fan triangulation of every polygon (as rouen's OBJ reader does): (n, 3, 3) array."""
    tris = []
    for polys in blocks.values():
        for poly in polys:
            for k in range(1, len(poly) - 1):
                tris.append([poly[0], poly[k], poly[k + 1]])
    return np.array(tris, float)


# ---------------------------------------------------------------------------------------------
# rouen's camera conventions (core/camera.h), written again here for the checks.


def look_at(eye, target):
    """rouen's Pose::LookAt: rotation columns right, down, forward (camera -> world)."""
    eye, target = np.array(eye, float), np.array(target, float)
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return np.column_stack([right, down, fwd])


def enu_from_az_el(az_deg, el_deg):
    a, e = math.radians(az_deg), math.radians(el_deg)
    return np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])


def pinhole_intrinsics(w, h, hfov_deg):
    f = 0.5 * w / math.tan(0.5 * math.radians(hfov_deg))
    return {"projection": "pinhole", "width": w, "height": h, "fx": f, "fy": f,
            "cx": 0.5 * w, "cy": 0.5 * h}


def equirect_intrinsics(w, h):
    return {"projection": "equirect", "width": w, "height": h}


def project(k, d):
    """rouen's Project() for a camera-frame direction d (no distortion)."""
    if k["projection"] == "pinhole":
        if d[2] <= 0:
            return None
        return np.array([k["fx"] * d[0] / d[2] + k["cx"], k["fy"] * d[1] / d[2] + k["cy"]])
    az = math.atan2(d[0], d[2]) % (2 * math.pi)
    el = math.asin(max(-1.0, min(1.0, -d[1] / np.linalg.norm(d))))
    return np.array([az / (2 * math.pi) * k["width"], (0.5 * math.pi - el) / math.pi * k["height"]])


def unproject_grid(k):
    """rouen's Unproject() through every pixel centre: (h, w, 3) camera-frame rays."""
    w, h = k["width"], k["height"]
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    if k["projection"] == "pinhole":
        d = np.stack([(u - k["cx"]) / k["fx"], (v - k["cy"]) / k["fy"], np.ones_like(u)], -1)
    else:
        az = u / w * 2 * math.pi
        el = 0.5 * math.pi - v / h * math.pi
        d = np.stack([np.cos(el) * np.sin(az), -np.sin(el), np.cos(el) * np.cos(az)], -1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def hit_mask(k, rotation, position, tris):
    """Pixels whose centre ray (rouen's camera model) hits a triangle of the building."""
    rays = unproject_grid(k).reshape(-1, 3) @ np.array(rotation).T
    o = np.array(position, float)
    hit = np.zeros(len(rays), bool)
    for t in tris:
        e1, e2 = t[1] - t[0], t[2] - t[0]
        p = np.cross(rays, e2)
        det = p @ e1
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - t[0]
        uu = (p @ s) * inv
        q = np.cross(s, e1)
        vv = (rays @ q) * inv
        tt = (q @ e2) * inv
        hit |= ok & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt > 1e-6)
    return hit.reshape(k["height"], k["width"])


# ---------------------------------------------------------------------------------------------
# Blender scene.


def material(name, spec, lambert=False):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    if lambert and spec["specular"] == 0:
        # Diagnostic only (--lambert): a Diffuse BSDF with roughness 0 is Lambert.
        nt = m.node_tree
        nt.nodes.remove(nt.nodes["Principled BSDF"])
        d = nt.nodes.new("ShaderNodeBsdfDiffuse")
        d.inputs["Color"].default_value = (*spec["base_color"], 1.0)
        d.inputs["Roughness"].default_value = 0.0
        nt.links.new(d.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
        return m
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (*spec["base_color"], 1.0)
    b.inputs["Roughness"].default_value = spec["roughness"]
    b.inputs["Specular"].default_value = spec["specular"]
    b.inputs["Metallic"].default_value = 0.0
    b.inputs["Sheen"].default_value = 0.0
    b.inputs["Clearcoat"].default_value = 0.0
    return m


def mesh_object(name, polys, mat):
    verts, faces = [], []
    for poly in polys:
        faces.append([len(verts) + k for k in range(len(poly))])
        verts.extend(poly)
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    ob.data.materials.append(mat)
    return ob


def tree_object(name, x, y, crown_mat, trunk_mat, trunk_r=0.25, trunk_h=3.2, crown_r=2.5,
                crown_z=5.0):
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=trunk_r, depth=trunk_h,
                                        location=(x, y, 0.5 * trunk_h))
    trunk = bpy.context.active_object
    trunk.name = name + "_trunk"
    trunk.data.materials.append(trunk_mat)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=10, radius=crown_r,
                                         location=(x, y, crown_z))
    crown = bpy.context.active_object
    crown.name = name + "_crown"
    crown.data.materials.append(crown_mat)
    return [trunk, crown]


SURROUNDINGS = {
    # name: (material, description, geometry for truth.json)
    "ground": ("ground", "4 x 4 km plane at z = 0 (to the horizon as seen from the mast)",
               {"box": [-2000, 2000, -2000, 2000, 0, 0]}),
    "wall": ("wall", "low wall 18 x 0.4 x 1.5 m", {"box": [-30, -12, -16.2, -15.8, 0, 1.5]}),
    "shed": ("shed", "box 4 x 3 x 2.5 m", {"box": [-16, -12, 6.5, 9.5, 0, 2.5]}),
    "car": ("car", "box 4.5 x 1.8 x 1.5 m", {"box": [23.75, 28.25, -16.9, -15.1, 0, 1.5]}),
    "tree0": ("crown", "trunk r 0.25 m h 3.2 m, crown sphere r 2.5 m at z 5 m",
              {"tree": [-6.0, 22.0]}),
    "tree1": ("crown", "trunk r 0.25 m h 3.2 m, crown sphere r 2.5 m at z 5 m",
              {"tree": [18.0, 14.0]}),
}


def ground_patch_object(name, box, patch, ground_mat, patch_mat):
    """The ground plane `box` (z0 == z1) cut by the patch's rectangle into a 3 x 3 grid of
    coplanar quads on 16 shared vertices; the centre quad (the patch) takes patch_mat."""
    x0, x1, y0, y1, z, _ = box
    px0, px1, py0, py1 = patch["rect"]
    if not (x0 < px0 < px1 < x1 and y0 < py0 < py1 < y1):
        raise RuntimeError(f"ground patch {patch['rect']} not inside the ground {box}")
    xs, ys = [x0, px0, px1, x1], [y0, py0, py1, y1]
    verts = [(x, y, z) for y in ys for x in xs]  # index 4 * j + i
    faces, mat_index = [], []
    for j in range(3):
        for i in range(3):
            a = 4 * j + i
            faces.append([a, a + 1, a + 5, a + 4])  # counter-clockwise seen from above
            mat_index.append(1 if (i, j) == (1, 1) else 0)
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    ob.data.materials.append(ground_mat)
    ob.data.materials.append(patch_mat)
    me.polygons.foreach_set("material_index", mat_index)
    me.update()
    return ob


def nishita_world(altitude_m=SITE["height_m"]):
    """Cycles' Nishita sky with its sun disc as the world, the only light, for a site at
    altitude_m; returns its node (the caller sets sun_elevation and sun_rotation per time)."""
    sc = bpy.context.scene
    world = bpy.data.worlds.new("sky")
    sc.world = world
    world.use_nodes = True
    nt = world.node_tree
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sky_type = "NISHITA"
    sky.sun_disc = True
    sky.sun_size = math.radians(SUN_DIAMETER_DEG)
    sky.sun_intensity = 1.0
    sky.altitude = altitude_m
    sky.air_density = 1.0
    sky.dust_density = 1.0
    sky.ozone_density = 1.0
    nt.links.new(sky.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    nt.nodes["Background"].inputs["Strength"].default_value = 1.0
    world.cycles.sampling_method = "MANUAL"
    world.cycles.sample_map_resolution = 2048
    return sky


def setup_render():
    """Cycles on the CPU, linear scene radiance out: the settings every frame is rendered with."""
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    c = sc.cycles
    c.device = "CPU"
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.max_bounces = 12
    c.diffuse_bounces = 8
    c.glossy_bounces = 8
    c.transmission_bounces = 0
    c.volume_bounces = 0
    c.transparent_max_bounces = 0
    c.caustics_reflective = True
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.film_exposure = 1.0
    sc.render.film_transparent = False
    sc.render.dither_intensity = 0.0
    sc.render.resolution_percentage = 100
    sc.render.pixel_aspect_x = sc.render.pixel_aspect_y = 1.0
    sc.render.use_border = False
    sc.render.threads_mode = "FIXED"
    sc.render.threads = 2
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    sc.display_settings.display_device = "sRGB"
    sc.sequencer_colorspace_settings.name = "Linear"
    sc.render.use_stamp = False
    for attr in dir(sc.render):
        if attr.startswith("use_stamp_"):
            try:
                setattr(sc.render, attr, False)
            except (AttributeError, TypeError):
                pass
    s = sc.render.image_settings
    s.file_format = "OPEN_EXR"
    s.color_mode = "RGB"


def build_scene(blocks, lambert=False, ground_patch=False):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mats = {n: material(n, s, lambert)
            for n, s in {**BLOCK_MATERIALS, **SURROUNDING_MATERIALS}.items()}
    building = [mesh_object("building_" + n, p, mats[n]) for n, p in blocks.items()]
    others = []
    for name, (mat, _, geo) in SURROUNDINGS.items():
        if name == "ground" and ground_patch:
            others.append(ground_patch_object(name, geo["box"], GROUND_PATCH, mats[mat],
                                              material("ground_patch", GROUND_PATCH, lambert)))
        elif "box" in geo:
            x0, x1, y0, y1, z0, z1 = geo["box"]
            if z0 == z1:
                polys = [[(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)]]
            else:
                polys = box_polygons(x0, x1, y0, y1, z0, z1)
            others.append(mesh_object(name, polys, mats[mat]))
        else:
            others.extend(tree_object(name, *geo["tree"], mats["crown"], mats["trunk"]))

    sky = nishita_world()
    setup_render()
    return building, others, sky


def blender_camera(name, kind, w, h, hfov_deg=None):
    cam = bpy.data.cameras.new(name)
    if kind == "pinhole":
        cam.type = "PERSP"
        cam.lens_unit = "MILLIMETERS"
        cam.sensor_fit = "HORIZONTAL"
        cam.sensor_width = 36.0
        cam.lens = 18.0 / math.tan(0.5 * math.radians(hfov_deg))
        cam.shift_x = cam.shift_y = 0.0
    else:
        cam.type = "PANO"
        cam.cycles.panorama_type = "EQUIRECTANGULAR"
        cam.cycles.latitude_min, cam.cycles.latitude_max = -0.5 * math.pi, 0.5 * math.pi
        cam.cycles.longitude_min, cam.cycles.longitude_max = -math.pi, math.pi
    cam.clip_start = 0.05
    cam.clip_end = 10000.0
    ob = bpy.data.objects.new(name, cam)
    bpy.context.scene.collection.objects.link(ob)
    return ob


# rouen camera axes in Blender camera axes, per projection (see the top of the file).
TO_ROUEN = {
    "pinhole": np.diag([1.0, -1.0, -1.0]),
    "equirect": np.diag([-1.0, -1.0, 1.0]),
}


def place_camera(ob, kind, rouen_rotation, position):
    rb = np.array(rouen_rotation) @ TO_ROUEN[kind]  # TO_ROUEN is its own inverse
    m = mathutils.Matrix.Identity(4)
    for r in range(3):
        for c in range(3):
            m[r][c] = rb[r, c]
        m[r][3] = position[r]
    ob.matrix_world = m
    bpy.context.view_layer.update()


def rouen_pose(ob, kind):
    """The camera's pose in rouen's convention, read back from Blender's matrix."""
    mw = ob.matrix_world
    rb = np.array([[mw[r][c] for c in range(3)] for r in range(3)])
    rb /= np.linalg.norm(rb, axis=0, keepdims=True)
    rr = rb @ TO_ROUEN[kind]
    return {"rotation": [[float(v) for v in row] for row in rr],
            "position": [float(mw[r][3]) for r in range(3)]}


def render(ob, k, path, samples, seed, depth="16", codec="PIZ", rgba=False):
    sc = bpy.context.scene
    sc.camera = ob
    sc.render.resolution_x, sc.render.resolution_y = k["width"], k["height"]
    sc.cycles.samples = samples
    sc.cycles.seed = seed
    s = sc.render.image_settings
    s.color_depth = depth
    s.exr_codec = codec
    s.color_mode = "RGBA" if rgba else "RGB"
    sc.render.filepath = path
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    return time.time() - t0


def read_exr(path):
    """(h, w, c) float array, row 0 at the top."""
    img = bpy.data.images.load(path, check_existing=False)
    img.colorspace_settings.name = "Non-Color"
    w, h = img.size
    c = img.channels
    a = np.empty(w * h * c, np.float32)
    img.pixels.foreach_get(a)
    bpy.data.images.remove(img)
    return a.reshape(h, w, c)[::-1]


def rouen_sun(rouen, utc):
    out = subprocess.run(
        [rouen, "sun", "--lat", str(SITE["lat_deg"]), "--lon", str(SITE["lon_deg"]),
         "--height", str(SITE["height_m"]), "--time", utc, "--json"],
        check=True, capture_output=True, text=True).stdout
    return json.loads(out)


# ---------------------------------------------------------------------------------------------
# Checks.


def sun_centroid(img, k, rotation, sun_dir, radius_deg):
    """Centroid (pixels) of the radiance above the background within 1.5 sun radii of the
    brightest pixel near rouen's sun, and its direction's angle from rouen's sun (deg)."""
    lum = img[..., :3].mean(-1).astype(np.float64)
    lum = np.where(np.isfinite(lum), lum, 0.0)
    rays = unproject_grid(k) @ np.array(rotation).T
    ang = np.degrees(np.arccos(np.clip(rays @ sun_dir, -1, 1)))
    near = ang < 3.0
    y, x = np.unravel_index(np.argmax(np.where(near, lum, -1)), lum.shape)
    ring = (ang > 2.5 * radius_deg) & (ang < 4.0 * radius_deg)
    bg = np.median(lum[ring]) if ring.any() else 0.0
    d0 = rays[y, x]
    disc = np.degrees(np.arccos(np.clip(rays @ d0, -1, 1))) < 1.5 * max(
        radius_deg, 0.5 * 360.0 / k["width"] * 1.5)
    wgt = np.where(disc, np.maximum(lum - bg, 0), 0)
    d = (rays * wgt[..., None]).sum((0, 1))
    d /= np.linalg.norm(d)
    v, u = np.nonzero(disc)
    cu = float((u + 0.5) @ wgt[v, u] / wgt[v, u].sum())
    cv = float((v + 0.5) @ wgt[v, u] / wgt[v, u].sum())
    off = math.degrees(math.acos(min(1.0, float(d @ sun_dir))))
    return cu, cv, off, float(lum[y, x])


def mask_check(ob, kind, k, pose, tris, building, others, world_node_strength, tmpdir, name):
    """Renders the building alone (transparent film, black sky) and compares its alpha > 0.5
    with the pixels whose centre ray, through rouen's camera model, hits the building."""
    sc = bpy.context.scene
    for o in others:
        o.hide_render = True
    bg = sc.world.node_tree.nodes["Background"]
    bg.inputs["Strength"].default_value = 0.0
    sc.render.film_transparent = True
    path = os.path.join(tmpdir, f"mask_{name}.exr")
    render(ob, k, path, 16, 0, depth="16", codec="ZIP", rgba=True)
    sc.render.film_transparent = False
    bg.inputs["Strength"].default_value = world_node_strength
    for o in others:
        o.hide_render = False
    alpha = read_exr(path)[..., 3] > 0.5
    ours = hit_mask(k, pose["rotation"], pose["position"], tris)
    diff = alpha != ours
    inter, union = (alpha & ours).sum(), (alpha | ours).sum()
    return {"blender_pixels": int(alpha.sum()), "rouen_model_pixels": int(ours.sum()),
            "differing_pixels": int(diff.sum()), "iou": float(inter / max(1, union))}


# ---------------------------------------------------------------------------------------------


def write_import_files(out, list_lines, cameras, log, t_start):
    """list.txt and cameras.json for `rouen import`; the render log's totals."""
    with open(os.path.join(out, "list.txt"), "w") as f:
        f.write("\n".join(list_lines) + "\n")
    with open(os.path.join(out, "cameras.json"), "w") as f:
        json.dump(cameras, f, indent=1)
    log["seconds_total"] = round(time.time() - t_start, 1)
    log["seconds_rendering"] = round(sum(r["seconds"] for r in log["renders"]), 1)


def render_sky_pano_float(out, rouen, slots, sky, cams, samples):
    """The mast sky panorama of each slot again, as the main loop renders it (same camera,
    samples and seed: 1000 * slot + its index among the slot's frames) but stored as float32,
    so the sun disc is not clipped. Nothing else is written."""
    ob, kind, k = cams["sky_pano"]
    index = list(cams).index("sky_pano")
    seconds = 0.0
    for s in slots:
        utc = f"{DATE}T{TIMES[s][1]}:00Z"
        sun = rouen_sun(rouen, utc)
        sky.sun_elevation = math.radians(sun["elevation_deg"])
        sky.sun_rotation = math.radians(sun["azimuth_deg"])
        fname = f"t{s}_sky_pano_f32.exr"
        secs = render(ob, k, os.path.join(out, fname), samples["sky_pano"], 1000 * s + index,
                      depth="32", codec="PXR24")
        seconds += secs
        print(f"rendered {fname} in {secs:.1f} s", flush=True)
    return seconds


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(description="Render rouen's Blender validation world")
    ap.add_argument("--out", required=True)
    ap.add_argument("--rouen", default=os.environ.get("ROUEN", "rouen"),
                    help="the rouen binary (for `rouen sun`)")
    ap.add_argument("--scale", type=float, default=1.0, help="multiplies every sample count")
    ap.add_argument("--times", default="", help="comma-separated slot indices (default: all)")
    ap.add_argument("--noise-check", action="store_true",
                    help="render arch0 of the first slot twice (two seeds) and report the noise")
    ap.add_argument("--no-checks", action="store_true")
    ap.add_argument("--lambert", action="store_true",
                    help="diagnostic, not the committed data: matte materials as Lambert "
                    "(Diffuse BSDF) instead of Principled BSDF")
    ap.add_argument("--ground-patch", action="store_true",
                    help="the ground with two albedos: GROUND_PATCH (a bright matte "
                    "rectangle north of the building) and the rest as before")
    ap.add_argument("--sky-pano-float", action="store_true",
                    help="only render each slot's sky panorama again as float32 "
                    "(t<k>_sky_pano_f32.exr, the sun disc unclipped); writes nothing else")
    a = ap.parse_args(argv)
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    tmpdir = os.path.join(out, ".tmp")
    if not a.sky_pano_float:
        os.makedirs(tmpdir, exist_ok=True)
    t_start = time.time()

    blocks = building_blocks()
    check_polygons_outward({"tower": blocks["tower"], "roof": blocks["roof"]}, (0.0, 0.0, 12.0))
    check_polygons_outward({"annex": blocks["annex"]}, None)
    if not a.sky_pano_float:
        write_obj(os.path.join(out, "building.obj"), blocks)
    tris = triangles(blocks)
    building, others, sky = build_scene(blocks, a.lambert, a.ground_patch)
    samples = {n: max(1, int(round(s * a.scale))) for n, s in SAMPLES.items()}

    # Cameras: fixed architecture views and panoramas; the sun camera follows the sun.
    cams = {}
    arch_k = pinhole_intrinsics(*ARCH_SIZE, ARCH_HFOV_DEG)
    for name, az, dist, eye_h, aim in ARCH_VIEWS:
        eye = (aim[0] + dist * math.sin(math.radians(az)),
               aim[1] + dist * math.cos(math.radians(az)), eye_h)
        ob = blender_camera(name, "pinhole", *ARCH_SIZE, ARCH_HFOV_DEG)
        place_camera(ob, "pinhole", look_at(eye, aim), eye)
        cams[name] = (ob, "pinhole", arch_k)
    pano_k = equirect_intrinsics(*PANO_SIZE)
    level = look_at((0, 0, 0), (0, 1, 0))  # rouen's Pose::Level(eye, 0, 0)
    for name, eye in (("ground_pano", GROUND_PANO_EYE), ("sky_pano", MAST_EYE)):
        ob = blender_camera(name, "equirect", *PANO_SIZE)
        place_camera(ob, "equirect", level, eye)
        cams[name] = (ob, "equirect", pano_k)
    sun_k = pinhole_intrinsics(*SUN_SIZE, SUN_HFOV_DEG)
    sun_ob = blender_camera("sun", "pinhole", *SUN_SIZE, SUN_HFOV_DEG)

    slots = range(len(TIMES))
    if a.times:
        slots = [int(s) for s in a.times.split(",")]
    if a.sky_pano_float:
        secs = render_sky_pano_float(out, a.rouen, slots, sky, cams, samples)
        print(f"done in {time.time() - t_start:.0f} s; render seconds {secs:.0f}", flush=True)
        return
    list_lines = ["# image  seconds  UTC  group  target   (HDR EXR: seconds = 1)"]
    cameras = {}
    for name, (ob, kind, k) in cams.items():
        cameras[f"group={name}"] = {"intrinsics": k, "pose": rouen_pose(ob, kind)}
    targets = {"arch0": "architecture", "arch1": "architecture", "arch2": "architecture",
               "ground_pano": "landscape", "sky_pano": "sky", "sun": "sun"}
    log = {"blender": bpy.app.version_string, "samples": samples, "renders": []}
    truth_times = []
    checks = {"sun_frames": [], "sky_panoramas": [], "masks": {}}

    for s in slots:
        local, utc_hm = TIMES[s]
        utc = f"{DATE}T{utc_hm}:00Z"
        sun = rouen_sun(a.rouen, utc)
        sky.sun_elevation = math.radians(sun["elevation_deg"])
        sky.sun_rotation = math.radians(sun["azimuth_deg"])
        sun_dir = enu_from_az_el(sun["azimuth_deg"], sun["elevation_deg"])
        place_camera(sun_ob, "pinhole", look_at(MAST_EYE, np.array(MAST_EYE) + sun_dir),
                     MAST_EYE)
        frames = {}
        for name, (ob, kind, k) in list(cams.items()) + [("sun", (sun_ob, "pinhole", sun_k))]:
            fname = f"t{s}_{name}.exr"
            path = os.path.join(out, fname)
            depth = "32" if name == "sun" else "16"
            codec = "PXR24"
            seed = 1000 * s + len(frames)
            secs = render(ob, k, path, samples[name if name in samples else "arch"], seed,
                          depth=depth, codec=codec)
            log["renders"].append({"file": fname, "seconds": round(secs, 2),
                                   "samples": samples[name if name in samples else "arch"]})
            print(f"rendered {fname} in {secs:.1f} s", flush=True)
            frames[name] = fname
            list_lines.append(f"{fname} 1 {utc} group={name} target={targets[name]}")
        cameras[frames["sun"]] = {"intrinsics": sun_k, "pose": rouen_pose(sun_ob, "pinhole")}
        truth_times.append({
            "slot": s, "local": f"{DATE}T{local}:00{ZONE}", "utc": utc,
            "heldout": s == HELDOUT, "rouen_sun": sun,
            "blender_sun_elevation_rad": sky.sun_elevation,
            "blender_sun_rotation_rad": sky.sun_rotation,
            "frames": frames})
        if not a.no_checks:
            # Sun frame: the disc's centroid against rouen's projection of its own sun.
            pose = cameras[frames["sun"]]["pose"]
            img = read_exr(os.path.join(out, frames["sun"]))
            dcam = np.array(pose["rotation"]).T @ sun_dir
            pred = project(sun_k, dcam)
            cu, cv, off, peak = sun_centroid(img, sun_k, pose["rotation"], sun_dir,
                                             sun["angular_radius_deg"])
            checks["sun_frames"].append({
                "slot": s, "rouen_pixel": [float(pred[0]), float(pred[1])],
                "disc_centroid_pixel": [cu, cv], "offset_deg": off, "peak_radiance": peak})
            # Sky panorama: where the disc is against rouen's equirect projection.
            pose = cameras["group=sky_pano"]["pose"]
            img = read_exr(os.path.join(out, frames["sky_pano"]))
            pred = project(pano_k, np.array(pose["rotation"]).T @ sun_dir)
            cu, cv, off, peak = sun_centroid(img, pano_k, pose["rotation"], sun_dir,
                                             sun["angular_radius_deg"])
            checks["sky_panoramas"].append({
                "slot": s, "rouen_pixel": [float(pred[0]), float(pred[1])],
                "disc_centroid_pixel": [cu, cv], "offset_deg": off,
                "pixel_deg": 360.0 / PANO_SIZE[0]})
            print("sun checks:", checks["sun_frames"][-1], checks["sky_panoramas"][-1], flush=True)

    if a.noise_check:
        ob, kind, k = cams["arch0"]
        s0 = slots[0]
        p1 = os.path.join(tmpdir, "noise_a.exr")
        p2 = os.path.join(tmpdir, "noise_b.exr")
        for p, seed in ((p1, 7), (p2, 8)):
            render(ob, k, p, samples["arch"], seed, depth="32", codec="ZIP")
        i1, i2 = read_exr(p1)[..., :3], read_exr(p2)[..., :3]
        bmask = hit_mask(k, cameras["group=arch0"]["pose"]["rotation"],
                         cameras["group=arch0"]["pose"]["position"], tris)
        m = 0.5 * (i1 + i2)
        rel = np.abs(i1 - i2) / np.sqrt(2) / np.maximum(m, 1e-6)
        checks["noise"] = {
            "view": "arch0", "slot": s0, "samples": samples["arch"],
            "median_rel_std_per_pixel_channel": float(np.median(rel[bmask])),
            "p90_rel_std_per_pixel_channel": float(np.percentile(rel[bmask], 90)),
            "rms_rel_std": float(np.sqrt(np.mean(rel[bmask] ** 2)))}
        print("noise:", checks["noise"], flush=True)

    if not a.no_checks:
        strength = bpy.context.scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value
        for name, (ob, kind, k) in cams.items():
            if name == "sky_pano":
                continue
            pose = cameras[f"group={name}"]["pose"]
            checks["masks"][name] = mask_check(ob, kind, k, pose, tris, building, others,
                                               strength, tmpdir, name)
            print("mask check", name, checks["masks"][name], flush=True)

    write_import_files(out, list_lines, cameras, log, t_start)
    truth = {
        "what": "rouen Blender/Cycles validation world (gen.py)",
        "frame": "east-north-up metres: x east, y north, z up (Blender's and rouen's world)",
        "site": SITE, "date": DATE, "zone": ZONE, "heldout_slot": HELDOUT,
        "sun_diameter_deg": SUN_DIAMETER_DEG,
        "sky": {"model": "Cycles Nishita, sun disc on, sun_intensity 1, air 1, dust 1, ozone 1",
                "altitude_m": SITE["height_m"], "background_strength": 1.0},
        "albedo_note": ("albedo = Principled BSDF base colour (linear RGB). Matte blocks have "
                        "roughness 1, specular 0: Cycles' Principled diffuse is then Burley's "
                        "(Disney) diffuse with its retro-reflection term, not Lambert: equal "
                        "to Lambert for light and view along the normal, brighter for light "
                        "at grazing incidence (1.4x for the held-out sun, 80 deg from the "
                        "normal, on the south walls seen from arch0)."),
        "blocks": {n: {**m, "in_building_obj": True, "glossy": m["specular"] > 0}
                   for n, m in BLOCK_MATERIALS.items()},
        "surroundings": {n: {"material": mat, **SURROUNDING_MATERIALS[mat], "shape": d, **geo}
                         for n, (mat, d, geo) in SURROUNDINGS.items()},
        "trunk_material": SURROUNDING_MATERIALS["trunk"],
        "times": truth_times,
        "cameras": {"architecture": [{"group": n, "azimuth_deg": az, "distance_m": d,
                                      "eye_height_m": e, "aim": aim}
                                     for n, az, d, e, aim in ARCH_VIEWS],
                    "ground_pano_eye": GROUND_PANO_EYE, "mast_eye": MAST_EYE,
                    "sun_hfov_deg": SUN_HFOV_DEG},
        "render": log,
    }
    if a.lambert:
        truth["lambert_diagnostic"] = True
    if a.ground_patch:
        truth["ground_patch"] = {
            **GROUND_PATCH, "in_building_obj": False,
            "shape": ("rectangle x0 x1 y0 y1 (m) of the ground plane at z = 0, cut out of it "
                      "(coplanar quads, shared vertices); the rest of the plane keeps the "
                      "ground material")}
    with open(os.path.join(out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)
    if not a.no_checks or a.noise_check:
        with open(os.path.join(out, "checks.json"), "w") as f:
            json.dump(checks, f, indent=1)
    for fn in os.listdir(tmpdir):
        os.remove(os.path.join(tmpdir, fn))
    os.rmdir(tmpdir)
    total = time.time() - t_start
    print(f"done in {total:.0f} s; render seconds {sum(r['seconds'] for r in log['renders']):.0f}",
          flush=True)


if __name__ == "__main__":
    main()
