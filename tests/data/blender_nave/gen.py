# A long low building with a street on its shady side, built from code and rendered by
# Blender/Cycles (world (b) of the issue "Right from the ground"):
#
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH [--scale S]
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH --plan
#
# A church: a nave 60 x 20 m (walls 14 m, a 52-degree gable roof of mildly glossy slate to a
# 26.8 m ridge), a west front 24 m wide and 30 m high, a low apse at the east end. North of it
# a street 9 m wide and a row of houses 14-16 m high (its north wall is in their shade and sees
# little sky); south of it an open square with trees; other low buildings and trees 40-120 m
# out; a rough ground (Principled diffuse, roughness 0.9). Lit by Cycles' Nishita sky with its
# sun disc (the only light) at five times of a summer day at Rouen. Everything a person on the
# ground can take: TWO HDR panoramas per time at eye height (one in the square, one in the
# street; each the landscape and the sky photo at once), a telephoto frame of the sun from the
# square, four architecture views at eye height (no camera above the roofline). One of them
# (`glint`) sees the roof's south slope near its mirror direction at the first training time.
#
# Beside each architecture frame, Cycles' Diffuse Direct and Indirect light passes
# (passes/t<k>_<view>_diffdir.exr, _diffind.exr), as ../blender_tower; beside the `glint` view
# also its Glossy Direct and Indirect passes (_glossdir.exr, _glossind.exr): the roof's
# specular light with its colour (Principled: the Fresnel-weighted specular tint) included.
#
# --plan writes nothing: it prints the geometry checks, the faces each camera sees and the
# mirror-angle table (no render).
#
# Shared code: ../blender_world/gen.py (imported as `base`: frames, rouen's camera
# conventions, Nishita sky, render settings, masks, sun checks, import files) and
# ../blender_tower/gen.py (imported as `tower`: check_outward, build_scene, light_pass_output
# for the diffuse and the glossy passes, the sun and mask checks, finish, the rough ground's
# material).
import argparse
import importlib.util
import json
import math
import os
import shutil
import sys
import time

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "blender_world"))
import gen as base  # noqa: E402  (../blender_world/gen.py)

_spec = importlib.util.spec_from_file_location("tower_gen",
                                               os.path.join(HERE, "..", "blender_tower", "gen.py"))
tower = importlib.util.module_from_spec(_spec)  # ../blender_tower/gen.py (main() is guarded)
_spec.loader.exec_module(tower)

SITE = {"lat_deg": 49.44, "lon_deg": 1.10, "height_m": 40.0}  # Rouen
DATE = "2026-06-20"
ZONE = "+02:00"  # CEST
TIMES = [  # (local, UTC): four training times and one held-out low evening sun (last)
    ("09:00", "07:00"),
    ("11:30", "09:30"),
    ("14:00", "12:00"),
    ("17:00", "15:00"),
    ("20:15", "18:15"),
]
HELDOUT = 4
GLINT_SLOT = 0  # the training time at which the `glint` view sees the south slope's mirror

MATTE = base.MATTE
GLOSSY = base.GLOSSY  # Principled roughness 0.35, specular 0.5 (as blender_tower's roof)
BLOCK_MATERIALS = {
    "facade": {"base_color": [0.64, 0.57, 0.47], **MATTE},
    "nave": {"base_color": [0.56, 0.48, 0.39], **MATTE},
    "apse": {"base_color": [0.68, 0.63, 0.54], **MATTE},
    "roof": {"base_color": [0.18, 0.19, 0.22], **GLOSSY},
}
SURROUNDING_MATERIALS = {
    "ground": {"base_color": [0.30, 0.25, 0.18], **tower.ROUGH_GROUND},
    "render": {"base_color": [0.70, 0.62, 0.52], **MATTE},
    "render2": {"base_color": [0.62, 0.60, 0.55], **MATTE},
    "brick": {"base_color": [0.55, 0.40, 0.32], **MATTE},
    "concrete": {"base_color": [0.60, 0.60, 0.58], **MATTE},
    "timber": {"base_color": [0.40, 0.30, 0.22], **MATTE},
    "stone": {"base_color": [0.55, 0.53, 0.50], **MATTE},
    "crown": {"base_color": [0.10, 0.22, 0.07], **MATTE},
    "trunk": {"base_color": [0.25, 0.17, 0.10], **MATTE},
}

# The building (east-north-up metres, origin at the nave's centre on the ground).
NAVE = {"x": (-30.0, 30.0), "half_width": 10.0, "wall_h": 14.0, "pitch_deg": 52.0}
RIDGE = NAVE["wall_h"] + NAVE["half_width"] * math.tan(math.radians(NAVE["pitch_deg"]))
FACADE = {"x": (-34.0, -30.0), "y": (-12.0, 12.0), "h": 30.0}
APSE = {"x": (30.0, 40.0), "y": (-7.0, 7.0), "h": 11.0}

STREET = {"y": (10.0, 19.0), "width_m": 9.0}
# name: (material, box x0 x1 y0 y1 z0 z1 | tree x y crown_r crown_z). Boxes are also written
# to surroundings.obj (walls and a flat roof each, as an extruded city-model footprint).
SURROUNDINGS = {
    "ground": ("ground", {"box": [-2000, 2000, -2000, 2000, 0, 0]}),
    # the row of houses across the street, north of the nave (contiguous, 14-16 m)
    "house_n1": ("render", {"box": [-54, -36, 19, 31, 0, 15.0]}),
    "house_n2": ("brick", {"box": [-36, -18, 19, 31, 0, 14.0]}),
    "house_n3": ("render2", {"box": [-18, 2, 19, 31, 0, 16.0]}),
    "house_n4": ("stone", {"box": [2, 22, 19, 31, 0, 14.5]}),
    "house_n5": ("brick", {"box": [22, 42, 19, 31, 0, 15.5]}),
    "house_n6": ("render", {"box": [42, 62, 19, 31, 0, 14.0]}),
    # other low buildings 40-120 m out
    "row_s": ("concrete", {"box": [-60, -20, -95, -82, 0, 10.0]}),
    "house_se": ("brick", {"box": [66, 80, -40, -26, 0, 9.0]}),
    "hall_nw": ("timber", {"box": [-115, -95, 22, 45, 0, 10.0]}),
    "house_sw": ("stone", {"box": [-100, -84, -62, -46, 0, 9.0]}),
    "school_e": ("concrete", {"box": [72, 96, 0, 22, 0, 12.0]}),
    "shed_s": ("timber", {"box": [15, 22, -80, -74, 0, 3.5]}),
    # trees: four in the square, three further out
    "tree_sq_w": ("crown", {"tree": [-20, -48, 3.5, 7.0]}),
    "tree_sq_s": ("crown", {"tree": [-8, -58, 3.5, 7.0]}),
    "tree_sq_sw": ("crown", {"tree": [-42, -62, 4.0, 7.5]}),
    "tree_s": ("crown", {"tree": [28, -95, 3.5, 7.0]}),
    "tree_e": ("crown", {"tree": [55, -12, 4.0, 8.0]}),
    "tree_nw": ("crown", {"tree": [-48, 42, 3.0, 6.5]}),
    "tree_far_s": ("crown", {"tree": [0, -110, 4.5, 8.5]}),
}

# Cameras. Architecture views: (name, eye, aim, horizontal field deg); eye height 1.7 m.
ARCH_SIZE = (402, 268)  # 3:2; 480x320 would make ~28 MB of noisy half-float EXR
EYE_H = 1.7
ARCH_VIEWS = [
    ("west", (-79.0, -8.0, EYE_H), (-34.0, -2.0, 14.0), 60.0),  # the west front, 45 m out
    ("se", (50.0, -80.0, EYE_H), (2.0, -4.0, 12.0), 60.0),  # south-south-east oblique, 90 m
    ("street", (-24.0, 17.5, EYE_H), (6.0, 10.0, 8.0), 75.0),  # in the street, the north wall
    ("glint", None, None, 60.0),  # south-west: the south slope near its mirror direction
]
# The glint view: the eye on the mirror of the sun (GLINT_SLOT) in the south slope's plane
# through GLINT_POINT, at eye height; aimed a little below and left of that point.
GLINT_POINT = (2.0, -8.0)  # x, y on the south slope
GLINT_AIM_SHIFT = (-8.0, 0.0, -9.0)
PANO_SIZE = (512, 256)
PANOS = {"pano_square": (0.0, -38.0, EYE_H),  # in the square, 28 m south of the south wall
         "pano_street": (0.0, 14.5, EYE_H)}  # in the street, mid-way between nave and houses
SUN_EYE = PANOS["pano_square"]
SUN_SIZE = (160, 160)
SUN_HFOV_DEG = 4.0
SAMPLES = {"arch": 512, "pano": 256, "sun": 32}


# ---------------------------------------------------------------------------------------------
# Geometry.


def building_faces():
    """[(block, face label, polygon)], counter-clockwise from outside, no bottom faces; the
    faces the blocks share are left out (the facade's east face is cut around the nave's
    section, the nave's east wall around the apse)."""
    x0, x1 = NAVE["x"]
    w, h, r = NAVE["half_width"], NAVE["wall_h"], RIDGE
    fx0, fx1 = FACADE["x"]
    fy0, fy1 = FACADE["y"]
    fh = FACADE["h"]
    ax0, ax1 = APSE["x"]
    ay0, ay1 = APSE["y"]
    ah = APSE["h"]
    f = []
    # facade: a box in front of the nave's west end, taller than the ridge
    f += [("facade", "west", [(fx0, fy1, 0), (fx0, fy0, 0), (fx0, fy0, fh), (fx0, fy1, fh)]),
          ("facade", "south", [(fx0, fy0, 0), (fx1, fy0, 0), (fx1, fy0, fh), (fx0, fy0, fh)]),
          ("facade", "north", [(fx1, fy1, 0), (fx0, fy1, 0), (fx0, fy1, fh), (fx1, fy1, fh)]),
          ("facade", "top", [(fx0, fy0, fh), (fx1, fy0, fh), (fx1, fy1, fh), (fx0, fy1, fh)]),
          ("facade", "east", [(fx1, fy0, 0), (fx1, -w, 0), (fx1, -w, fh), (fx1, fy0, fh)]),
          ("facade", "east", [(fx1, w, 0), (fx1, fy1, 0), (fx1, fy1, fh), (fx1, w, fh)]),
          ("facade", "east", [(fx1, -w, h), (fx1, 0, r), (fx1, 0, fh), (fx1, -w, fh)]),
          ("facade", "east", [(fx1, 0, r), (fx1, w, h), (fx1, w, fh), (fx1, 0, fh)])]
    # nave: the long walls, the east wall around the apse and the east gable
    f += [("nave", "south", [(x0, -w, 0), (x1, -w, 0), (x1, -w, h), (x0, -w, h)]),
          ("nave", "north", [(x1, w, 0), (x0, w, 0), (x0, w, h), (x1, w, h)]),
          ("nave", "east", [(x1, -w, 0), (x1, ay0, 0), (x1, ay0, ah), (x1, -w, ah)]),
          ("nave", "east", [(x1, ay1, 0), (x1, w, 0), (x1, w, ah), (x1, ay1, ah)]),
          ("nave", "east", [(x1, -w, ah), (x1, w, ah), (x1, w, h), (x1, -w, h)]),
          ("nave", "east", [(x1, -w, h), (x1, w, h), (x1, 0, r)])]
    # roof: two slopes from the eaves to the ridge
    f += [("roof", "south", [(x0, -w, h), (x1, -w, h), (x1, 0, r), (x0, 0, r)]),
          ("roof", "north", [(x1, w, h), (x0, w, h), (x0, 0, r), (x1, 0, r)])]
    # apse: a low box against the east wall, flat roof
    f += [("apse", "south", [(ax0, ay0, 0), (ax1, ay0, 0), (ax1, ay0, ah), (ax0, ay0, ah)]),
          ("apse", "east", [(ax1, ay0, 0), (ax1, ay1, 0), (ax1, ay1, ah), (ax1, ay0, ah)]),
          ("apse", "north", [(ax1, ay1, 0), (ax0, ay1, 0), (ax0, ay1, ah), (ax1, ay1, ah)]),
          ("apse", "top", [(ax0, ay0, ah), (ax1, ay0, ah), (ax1, ay1, ah), (ax0, ay1, ah)])]
    return f


FACE_DIRECTIONS = {"south": (0, -1, 0), "north": (0, 1, 0), "east": (1, 0, 0),
                   "west": (-1, 0, 0), "top": (0, 0, 1)}


# Sloped blocks: the least up-component of their faces' normals (walls face their way level).
SLOPED = {"roof": 0.5}


def check_faces(faces):
    """Each face's normal points the way its label says (walls horizontally, the SLOPED blocks'
    slopes up and to their side), and tower.check_outward: outward as seen from the whole
    building."""
    for block, label, poly in faces:
        n = base.polygon_normal(poly)
        want = np.array(FACE_DIRECTIONS[label], float)
        if block in SLOPED:
            ok = n[2] > SLOPED[block] and n @ want > 0.5
        else:
            ok = n @ want > 0.999
        if not ok:
            raise RuntimeError(f"{block} {label}: normal {n} of {poly}")
    blocks = {}
    for block, _, poly in faces:
        blocks.setdefault(block, []).append(poly)
    tower.check_outward(blocks)
    return blocks


def surrounding_boxes():
    return tower.surrounding_boxes(SURROUNDINGS)


# ---------------------------------------------------------------------------------------------
# Ray casting (numpy) for the plan: which face each pixel of rouen's camera model sees first,
# the roof's mirror angles, shadows.


class Tracer:
    """Nearest hits against the building's triangles, the surrounding boxes and the trees'
    crowns (spheres; trunks left out). Hit ids: building face index >= 0, -2 surroundings box,
    -3 tree crown, -1 nothing."""

    def __init__(self, faces):
        tris, ids = [], []
        for i, (_, _, poly) in enumerate(faces):
            for k in range(1, len(poly) - 1):
                tris.append([poly[0], poly[k], poly[k + 1]])
                ids.append(i)
        for b in surrounding_boxes().values():
            for poly in base.box_polygons(*b):
                for k in range(1, len(poly) - 1):
                    tris.append([poly[0], poly[k], poly[k + 1]])
                    ids.append(-2)
        self.tris = np.array(tris, float)
        self.ids = np.array(ids)
        self.spheres = [(np.array([g["tree"][0], g["tree"][1], g["tree"][3]], float), g["tree"][2])
                        for _, (_, g) in SURROUNDINGS.items() if "tree" in g]

    def nearest(self, origins, rays):
        n = len(rays)
        o = np.broadcast_to(np.asarray(origins, float), (n, 3))
        best = np.full(n, np.inf)
        hid = np.full(n, -1)
        for t, i in zip(self.tris, self.ids):
            e1, e2 = t[1] - t[0], t[2] - t[0]
            p = np.cross(rays, e2)
            det = p @ e1
            ok = np.abs(det) > 1e-12
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            s = o - t[0]
            u = np.einsum("ij,ij->i", p, s) * inv
            q = np.cross(s, e1)
            v = np.einsum("ij,ij->i", rays, q) * inv
            tt = (q @ e2) * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (tt > 1e-6) & (tt < best)
            best[hit] = tt[hit]
            hid[hit] = i
        for c, r in self.spheres:
            oc = o - c
            b = np.einsum("ij,ij->i", oc, rays)
            disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
            tt = -b - np.sqrt(np.maximum(disc, 0))
            hit = (disc > 0) & (tt > 1e-6) & (tt < best)
            best[hit] = tt[hit]
            hid[hit] = -3
        return best, hid


def camera_rays(k, rotation):
    return (base.unproject_grid(k) @ np.array(rotation).T).reshape(-1, 3)


def face_table(faces, hid):
    """Pixels per block and face label."""
    out = {}
    for i, (block, label, _) in enumerate(faces):
        c = int((hid == i).sum())
        if c:
            key = f"{block}.{label}"
            out[key] = out.get(key, 0) + c
    out["surroundings"] = int((hid == -2).sum())
    out["trees"] = int((hid == -3).sum())
    return out


def mirror_entry(faces, tracer, k, pose, sun_dir, dist, hid):
    """Per roof slope seen by the camera: the angle between the mirror of each pixel's ray in
    the slope and the sun, its minimum over the slope's pixels (and over its sunlit ones), the
    pixel there, and how many sunlit pixels are within 5, 10 and 20 degrees."""
    rays = camera_rays(k, pose["rotation"])
    res = {}
    for i, (block, label, poly) in enumerate(faces):
        if block != "roof":
            continue
        m = hid == i
        n = base.polygon_normal(poly)
        e = {"pixels": int(m.sum()),
             "sun_incidence_deg": round(math.degrees(math.acos(float(np.clip(n @ sun_dir, -1, 1)))), 2)}
        if m.any():
            d = rays[m]
            r = d - 2 * (d @ n)[:, None] * n
            ang = np.degrees(np.arccos(np.clip(r @ sun_dir, -1, 1)))
            pts = np.array(pose["position"]) + d * dist[m][:, None] + 1e-3 * n
            _, sh = tracer.nearest(pts, np.broadcast_to(sun_dir, pts.shape).copy())
            lit = (sh == -1) & (n @ sun_dir > 0)
            idx = np.flatnonzero(m)
            j = int(np.argmin(ang))
            e.update({"min_mirror_deg": round(float(ang.min()), 2),
                      "min_pixel": [int(idx[j] % k["width"]), int(idx[j] // k["width"])],
                      "sunlit_pixels": int(lit.sum())})
            if lit.any():
                al = ang[lit]
                e.update({"min_mirror_sunlit_deg": round(float(al.min()), 2),
                          "sunlit_within_5deg": int((al < 5).sum()),
                          "sunlit_within_10deg": int((al < 10).sum()),
                          "sunlit_within_20deg": int((al < 20).sum())})
        res[f"roof.{label}"] = e
    return res


def glint_camera(sun_dir):
    """Eye and aim of the glint view: the eye at eye height on the line through GLINT_POINT
    (on the south slope) along the mirror of the sun in the slope's plane."""
    south = [p for b, lab, p in building_faces() if b == "roof" and lab == "south"][0]
    n = base.polygon_normal(south)
    gx, gy = GLINT_POINT
    w, h = NAVE["half_width"], NAVE["wall_h"]
    p = np.array([gx, gy, h + (w + gy) * math.tan(math.radians(NAVE["pitch_deg"]))])
    d = sun_dir - 2 * (sun_dir @ n) * n  # the view ray that mirrors to the sun
    if d[2] <= 0:
        raise RuntimeError("the sun's mirror in the south slope does not point up")
    eye = p - d * (p[2] - EYE_H) / d[2]
    return tuple(float(v) for v in eye), tuple(float(v) for v in p + np.array(GLINT_AIM_SHIFT))


def sun_dir_of(sun):
    return base.enu_from_az_el(sun["azimuth_deg"], sun["elevation_deg"])


# ---------------------------------------------------------------------------------------------
# Blender scene.


def roof_node_settings():
    """What Cycles renders the roof with (recorded in truth.json)."""
    m = bpy.data.materials["roof"].node_tree.nodes["Principled BSDF"]
    return {"distribution": m.distribution, "subsurface_method": m.subsurface_method,
            "specular_tint": m.inputs["Specular Tint"].default_value,
            "anisotropic": m.inputs["Anisotropic"].default_value,
            "ggx_alpha": GLOSSY["roughness"] ** 2,
            "fresnel_f0": 0.08 * GLOSSY["specular"]}


# ---------------------------------------------------------------------------------------------


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(description="Render rouen's nave-and-street world")
    ap.add_argument("--out", required=True)
    ap.add_argument("--rouen", default=os.environ.get("ROUEN", "rouen"))
    ap.add_argument("--scale", type=float, default=1.0, help="multiplies every sample count")
    ap.add_argument("--times", default="", help="comma-separated slot indices (default: all)")
    ap.add_argument("--no-checks", action="store_true")
    ap.add_argument("--only", default="",
                    help="comma-separated camera names to render (default: all; the sun frame "
                         "always): a second copy of some views, see --seed-offset")
    ap.add_argument("--seed-offset", type=int, default=0,
                    help="added to every frame's Cycles seed: another render of the same world, "
                         "whose noise is independent (tests/probe/noise_ceiling.py)")
    ap.add_argument("--plan", action="store_true",
                    help="print the geometry, visibility and mirror checks; render nothing")
    a = ap.parse_args(argv)
    base.SITE.update(SITE)  # `rouen sun` (base.rouen_sun) asks for this site
    out = os.path.abspath(a.out)
    t_start = time.time()

    faces = building_faces()
    blocks = check_faces(faces)
    tracer = Tracer(faces)
    slots = [int(s) for s in a.times.split(",")] if a.times else list(range(len(TIMES)))
    suns = {s: base.rouen_sun(a.rouen, f"{DATE}T{TIMES[s][1]}:00Z") for s in range(len(TIMES))}

    # Camera poses (rouen's convention) and intrinsics, computed here; Blender's cameras are
    # placed from them and read back (base.rouen_pose) for cameras.json.
    views = []
    for name, eye, aim, hfov in ARCH_VIEWS:
        if name == "glint":
            eye, aim = glint_camera(sun_dir_of(suns[GLINT_SLOT]))
        views.append((name, eye, aim, hfov))
    plan_cams = {}
    for name, eye, aim, hfov in views:
        plan_cams[name] = (base.pinhole_intrinsics(*ARCH_SIZE, hfov),
                           {"rotation": base.look_at(eye, aim).tolist(), "position": list(eye)})
    pano_k = base.equirect_intrinsics(*PANO_SIZE)
    level = base.look_at((0, 0, 0), (0, 1, 0))  # rouen's Pose::Level(eye, 0, 0)
    for name, eye in PANOS.items():
        plan_cams[name] = (pano_k, {"rotation": level.tolist(), "position": list(eye)})

    # Plan: the faces each camera sees first, the building hidden by surroundings, the sun's
    # line of sight from the sun camera, the mirror-angle table.
    visibility, mirror, sun_sight, sun_in_views = {}, [], [], []
    all_tris = base.triangles(blocks)
    hits = {}
    for name, (k, pose) in plan_cams.items():
        rays = camera_rays(k, pose["rotation"])
        dist, hid = tracer.nearest(pose["position"], rays)
        hits[name] = (dist, hid)
        anyb = base.hit_mask(k, pose["rotation"], pose["position"], all_tris).reshape(-1)
        visibility[name] = {"pixels": face_table(faces, hid),
                            "building_pixels_hidden_by_surroundings": int((anyb & (hid < 0)).sum())}
        print("sees", name, visibility[name], flush=True)
    for s in range(len(TIMES)):
        sd = sun_dir_of(suns[s])
        _, sh = tracer.nearest(SUN_EYE, sd[None, :])
        sun_sight.append({"slot": s, "blocked": bool(sh[0] != -1)})
        if sh[0] != -1:
            raise RuntimeError(f"slot {s}: the sun is hidden from the sun camera ({sh[0]})")
        for name, (k, pose) in plan_cams.items():  # no sun disc in an architecture view
            if k["projection"] != "pinhole":
                continue
            dcam = np.array(pose["rotation"]).T @ sd
            m = k["fx"] * math.tan(math.radians(3.0))  # the disc and 3 degrees around it
            uv = base.project(k, dcam)
            inside = uv is not None and (-m < uv[0] < k["width"] + m and -m < uv[1] < k["height"] + m)
            # the sun's centre and a ring 1 degree around it: all hidden, or the view fails
            e1 = np.cross(sd, [0.0, 0.0, 1.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(sd, e1)
            ring = [sd] + [math.cos(math.radians(1)) * sd + math.sin(math.radians(1)) *
                           (math.cos(a) * e1 + math.sin(a) * e2)
                           for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)]
            _, sh = tracer.nearest(pose["position"], np.array(ring))
            if inside:
                print(f"slot {s}: the sun is within 3 deg of view {name} at {uv}, "
                      f"{'hidden' if (sh != -1).all() else 'VISIBLE'}", flush=True)
                if (sh == -1).any():
                    sun_in_views.append((s, name))
        row = {"slot": s, "local": TIMES[s][0], "cameras": {}}
        for name, (k, pose) in plan_cams.items():
            row["cameras"][name] = mirror_entry(faces, tracer, k, pose, sd, *hits[name])
        mirror.append(row)
        print("mirror", s, json.dumps({n: {f: (e.get("min_mirror_deg"), e.get("min_mirror_sunlit_deg"),
                                                e.get("sunlit_within_10deg"))
                                           for f, e in c.items() if e["pixels"]}
                                       for n, c in row["cameras"].items()}), flush=True)
    if sun_in_views:
        raise RuntimeError(f"the sun disc is seen in architecture views: {sun_in_views}")
    if a.plan:
        print("views:", views)
        print(f"ridge {RIDGE:.2f} m; suns:",
              {s: (round(v["azimuth_deg"], 2), round(v["elevation_deg"], 2)) for s, v in suns.items()})
        return

    tmpdir = os.path.join(out, ".tmp")
    os.makedirs(tmpdir, exist_ok=True)
    os.makedirs(os.path.join(out, "passes"), exist_ok=True)  # not photos: rouen import skips it
    base.write_obj(os.path.join(out, "building.obj"), blocks)
    tower.write_surroundings_obj(os.path.join(out, "surroundings.obj"), SURROUNDINGS)
    tower.write_trees_csv(os.path.join(out, "trees.csv"), SURROUNDINGS)
    tris = base.triangles(blocks)
    building, others, sky = tower.build_scene(blocks, BLOCK_MATERIALS, SURROUNDING_MATERIALS,
                                              SURROUNDINGS)
    passes = tower.light_pass_output(tmpdir)
    gloss = tower.light_pass_output(tmpdir, "glossy")
    samples = {n: max(1, int(round(s * a.scale))) for n, s in SAMPLES.items()}

    cams = {}
    for name, eye, aim, hfov in views:
        k = plan_cams[name][0]
        ob = base.blender_camera(name, "pinhole", *ARCH_SIZE, hfov)
        base.place_camera(ob, "pinhole", base.look_at(eye, aim), eye)
        cams[name] = (ob, "pinhole", k, "arch")
    for name, eye in PANOS.items():
        ob = base.blender_camera(name, "equirect", *PANO_SIZE)
        base.place_camera(ob, "equirect", level, eye)
        cams[name] = (ob, "equirect", pano_k, "pano")
    unknown = set(a.only.split(",")) - set(cams) if a.only else set()
    if unknown:
        raise SystemExit(f"--only: no camera {', '.join(sorted(unknown))} (cameras: {', '.join(cams)})")
    sun_k = base.pinhole_intrinsics(*SUN_SIZE, SUN_HFOV_DEG)
    sun_ob = base.blender_camera("sun", "pinhole", *SUN_SIZE, SUN_HFOV_DEG)
    targets = {n: "architecture" for n, *_ in views}
    targets.update({n: "landscape+sky" for n in PANOS})
    targets["sun"] = "sun"

    list_lines = ["# image  seconds  UTC  group  target   (HDR EXR: seconds = 1)"]
    cameras = {f"group={n}": {"intrinsics": k, "pose": base.rouen_pose(ob, kind)}
               for n, (ob, kind, k, _) in cams.items()}
    for n, (k, pose) in plan_cams.items():  # Blender's cameras are where the plan put them
        got = cameras[f"group={n}"]["pose"]
        if (np.abs(np.array(got["rotation"]) - np.array(pose["rotation"])).max() > 1e-5 or
                np.abs(np.array(got["position"]) - np.array(pose["position"])).max() > 1e-4):
            raise RuntimeError(f"camera {n}: Blender's pose {got} is not the plan's {pose}")
    log = {"blender": bpy.app.version_string, "samples": samples, "renders": []}
    truth_times, checks = [], {"sun_frames": [], "masks": {}}
    for s in slots:
        local, utc_hm = TIMES[s]
        utc = f"{DATE}T{utc_hm}:00Z"
        sun = suns[s]
        sky.sun_elevation = math.radians(sun["elevation_deg"])
        sky.sun_rotation = math.radians(sun["azimuth_deg"])
        sun_dir = sun_dir_of(sun)
        base.place_camera(sun_ob, "pinhole", base.look_at(SUN_EYE, np.array(SUN_EYE) + sun_dir),
                          SUN_EYE)
        frames = {}
        for name, (ob, kind, k, role) in list(cams.items()) + [
                ("sun", (sun_ob, "pinhole", sun_k, "sun"))]:
            if a.only and name != "sun" and name not in a.only.split(","):
                continue
            fname = f"t{s}_{name}.exr"
            passes.mute = role != "arch"
            gloss.mute = name != "glint"
            seed = 1000 * s + len(frames) + a.seed_offset
            n = samples[role]
            cpu0 = time.process_time()
            secs = base.render(ob, k, os.path.join(out, fname), n, seed,
                               depth="32" if role == "sun" else "16", codec="PXR24")
            cpu = time.process_time() - cpu0
            written = []
            if role == "arch":
                written = ["diffdir", "diffind"] + (["glossdir", "glossind"] if name == "glint" else [])
            for p in written:
                shutil.move(os.path.join(tmpdir, f"{p}{bpy.context.scene.frame_current:04d}.exr"),
                            os.path.join(out, "passes", f"t{s}_{name}_{p}.exr"))
            log["renders"].append({"file": fname, "seconds": round(secs, 2),
                                   "cpu_seconds": round(cpu, 2), "samples": n})
            print(f"rendered {fname} in {secs:.1f} s ({cpu:.1f} s CPU)", flush=True)
            frames[name] = fname
            list_lines.append(f"{fname} 1 {utc} group={name} target={targets[name]}")
        cameras[frames["sun"]] = {"intrinsics": sun_k, "pose": base.rouen_pose(sun_ob, "pinhole")}
        truth_times.append({"slot": s, "local": f"{DATE}T{local}:00{ZONE}", "utc": utc,
                            "heldout": s == HELDOUT, "rouen_sun": sun, "frames": frames})
        if not a.no_checks:
            checks["sun_frames"].append(tower.sun_frame_check(
                out, frames["sun"], sun_k, cameras[frames["sun"]]["pose"], sun_dir, sun, s))

    passes.mute = gloss.mute = True
    if not a.no_checks:
        checks["masks"] = tower.mask_checks(cams, cameras, tris, building, others, tmpdir)

    base.write_import_files(out, list_lines, cameras, log, t_start)
    # CPU seconds of the whole process (its threads): on 2 idle cores the wall time is about
    # half of it; the wall times above depend on what else the machine runs.
    log["cpu_seconds_total"] = round(time.process_time(), 1)
    log["cpu_seconds_rendering"] = round(sum(r["cpu_seconds"] for r in log["renders"]), 1)
    truth = {
        "what": ("rouen Blender/Cycles validation world: a nave with a street on its shady side, "
                 "photographed from the ground (gen.py)"),
        "frame": "east-north-up metres: x east, y north, z up (Blender's and rouen's world)",
        "site": SITE, "date": DATE, "zone": ZONE, "heldout_slot": HELDOUT,
        "glint_slot": GLINT_SLOT,
        "sun_diameter_deg": base.SUN_DIAMETER_DEG,
        "sky": {"model": "Cycles Nishita, sun disc on, sun_intensity 1, air 1, dust 1, ozone 1",
                "altitude_m": SITE["height_m"], "background_strength": 1.0},
        "albedo_note": ("albedo = Principled BSDF base colour (linear RGB); matte blocks: "
                        "roughness 1, specular 0 (Burley's diffuse, rouen retro 1); the ground: "
                        "roughness 0.9; the roof: specular 0.5, roughness 0.35 (glossy). The "
                        "passes/*_diffdir/_diffind frames are Cycles' Diffuse Direct/Indirect "
                        "passes (the diffuse light without the albedo); *_glossdir/_glossind "
                        "its Glossy Direct/Indirect passes (the specular light, Fresnel "
                        "included)."),
        "blocks": {n: {**m, "in_building_obj": True, "glossy": m["specular"] > 0}
                   for n, m in BLOCK_MATERIALS.items()},
        "roof_shader": roof_node_settings(),
        "building": {"nave": {**NAVE, "ridge_m": RIDGE}, "facade": FACADE, "apse": APSE,
                     "faces": [{"block": b, "face": lab, "normal": base.polygon_normal(p).tolist()}
                               for b, lab, p in faces]},
        "street": STREET,
        "surroundings": {n: {"material": mat, **SURROUNDING_MATERIALS[mat], **geo,
                             "in_surroundings_obj": "box" in geo and geo["box"][4] != geo["box"][5]}
                         for n, (mat, geo) in SURROUNDINGS.items()},
        "times": truth_times,
        "cameras": {"architecture": [{"group": n, "eye": list(e), "aim": list(t),
                                      "hfov_deg": h, "size": list(ARCH_SIZE)}
                                     for n, e, t, h in views],
                    "panoramas": {n: list(e) for n, e in PANOS.items()},
                    "sun_eye": list(SUN_EYE), "sun_hfov_deg": SUN_HFOV_DEG},
        "visibility": {"note": ("pixels of rouen's camera model whose centre ray first hits "
                                "each block.face (numpy ray cast; trunks left out)"),
                       **visibility},
        "mirror": {"note": ("per time, camera and roof slope: the angle between each roof "
                            "pixel's ray mirrored in the slope and rouen's sun; min over the "
                            "slope's pixels and over its sunlit ones (shadow rays against the "
                            "building, the boxes and the crowns), sunlit pixels within 5/10/20 "
                            "deg; the sun's incidence on the slope"),
                   "table": mirror},
        "sun_line_of_sight": sun_sight,
        "render": log,
    }
    tower.finish(out, truth, None if a.no_checks else checks, tmpdir, t_start)


if __name__ == "__main__":
    main()
