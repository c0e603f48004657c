# A validation world photographed only from the ground, built from code and rendered by
# Blender/Cycles (issue "Right from the ground"):
#
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH [--scale S]
#
# An 82 m campanile (a 10 m base, an 8 m shaft, a belfry open on its four sides, a mildly
# glossy pyramid roof) on a rough ground (Principled diffuse, roughness 0.9), houses, a block,
# a shed, a wall and trees 45-115 m away, lit by Cycles' Nishita sky with its sun disc (the
# only light) at five times of one day. Everything a person standing on the ground can take:
# ONE HDR panorama per time at eye height 30 m south of the tower (the tower hides part of the
# sky and the ground north of it; it is both the landscape and the sky photo), a telephoto
# frame of the sun from the same place, three architecture views 100 m out. No camera above
# the roofline.
#
# Beside each architecture frame, Cycles' Diffuse Direct and Diffuse Indirect light passes
# (passes/t<k>_<view>_diffdir.exr, _diffind.exr): the light a pixel's surface receives, without its
# albedo. Direct is the sun and the sky (the world, through the building's occlusion);
# indirect is every bounce off the ground, the surroundings and the building. For a surface
# of Burley's diffuse (Principled, roughness 1) they are (E_sun D + E_sky A) / pi and
# E_indirect A / pi in rouen's terms (solve/retro.h).
#
# Shared with ../blender_world/gen.py (imported from there): the frames (Blender's world frame
# is rouen's east-north-up), rouen's camera conventions, the render settings, the checks.
import argparse
import json
import math
import os
import shutil
import sys
import time

import bpy
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "blender_world"))
import gen as base  # noqa: E402  (../blender_world/gen.py)

SITE = {"lat_deg": 43.77, "lon_deg": 11.25, "height_m": 50.0}
DATE = "2026-10-02"
ZONE = "+02:00"  # CEST
TIMES = [  # (local, UTC): four training times and one held-out low-sun time (last)
    ("09:00", "07:00"),
    ("11:30", "09:30"),
    ("14:00", "12:00"),
    ("16:30", "14:30"),
    ("17:30", "15:30"),
]
HELDOUT = 4

MATTE = base.MATTE
GLOSSY = base.GLOSSY
BLOCK_MATERIALS = {
    "base": {"base_color": [0.55, 0.52, 0.46], **MATTE},
    "shaft": {"base_color": [0.62, 0.50, 0.40], **MATTE},
    "belfry": {"base_color": [0.70, 0.66, 0.58], **MATTE},
    "roof": {"base_color": [0.20, 0.21, 0.24], **GLOSSY},
}
ROUGH_GROUND = {"roughness": 0.9, "specular": 0.0}
SURROUNDING_MATERIALS = {
    "ground": {"base_color": [0.30, 0.25, 0.18], **ROUGH_GROUND},
    "render": {"base_color": [0.70, 0.62, 0.52], **MATTE},
    "brick": {"base_color": [0.55, 0.40, 0.32], **MATTE},
    "concrete": {"base_color": [0.60, 0.60, 0.58], **MATTE},
    "timber": {"base_color": [0.40, 0.30, 0.22], **MATTE},
    "stone": {"base_color": [0.55, 0.53, 0.50], **MATTE},
    "crown": {"base_color": [0.10, 0.22, 0.07], **MATTE},
    "trunk": {"base_color": [0.25, 0.17, 0.10], **MATTE},
}
# name: (material, box x0 x1 y0 y1 z0 z1 | tree x y crown_r crown_z)
SURROUNDINGS = {
    "ground": ("ground", {"box": [-2000, 2000, -2000, 2000, 0, 0]}),
    "house_e": ("render", {"box": [48, 60, -12, 6, 0, 12]}),
    "house_w": ("brick", {"box": [-78, -62, 8, 26, 0, 9]}),
    "block_ne": ("concrete", {"box": [35, 55, 55, 80, 0, 15]}),
    "shed_n": ("timber", {"box": [-25, -15, 45, 52, 0, 4]}),
    "wall_s": ("stone", {"box": [-40, -10, -55, -54.5, 0, 2]}),
    "tree_se": ("crown", {"tree": [30, -60, 3.5, 7.0]}),
    "tree_w": ("crown", {"tree": [-48, -22, 4.0, 7.5]}),
    "tree_nw": ("crown", {"tree": [-20, 60, 4.0, 8.0]}),
    "tree_e": ("crown", {"tree": [60, 30, 3.5, 7.0]}),
    "tree_n": ("crown", {"tree": [8, 48, 3.0, 6.5]}),
}

# Architecture views (name, azimuth of the eye from the aim point, distance m, eye height m,
# aim): portrait frames, 50 deg vertical field.
ARCH_SIZE = (320, 640)
ARCH_VFOV_DEG = 50.0
ARCH_HFOV_DEG = 2 * math.degrees(math.atan(ARCH_SIZE[0] / ARCH_SIZE[1] *
                                           math.tan(math.radians(0.5 * ARCH_VFOV_DEG))))
AIM = (0.0, 0.0, 41.0)
ARCH_VIEWS = [
    ("arch_se", 135.0, 100.0, 1.7, AIM),
    ("arch_sw", 225.0, 100.0, 1.7, AIM),
    ("arch_n", 355.0, 100.0, 1.7, AIM),
]
PANO_SIZE = (512, 256)
PANO_EYE = (0.0, -30.0, 1.7)  # 30 m south of the tower's axis, eye height
SUN_SIZE = (160, 160)
SUN_HFOV_DEG = 4.0
SAMPLES = {"arch": 512, "pano": 256, "sun": 32}


def building_blocks():
    """{block: [polygon, ...]}, counter-clockwise from outside, no bottom faces."""
    def quad_x(x, y0, y1, z0, z1, out):  # wall in the plane x = const facing +x or -x
        return ([(x, y0, z0), (x, y1, z0), (x, y1, z1), (x, y0, z1)] if out > 0 else
                [(x, y1, z0), (x, y0, z0), (x, y0, z1), (x, y1, z1)])

    def quad_y(y, x0, x1, z0, z1, out):  # wall in the plane y = const facing +y or -y
        return ([(x1, y, z0), (x0, y, z0), (x0, y, z1), (x1, y, z1)] if out > 0 else
                [(x0, y, z0), (x1, y, z0), (x1, y, z1), (x0, y, z1)])

    def level(x0, x1, y0, y1, z, up):  # horizontal rectangle facing up or down
        return ([(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)] if up else
                [(x0, y0, z), (x0, y1, z), (x1, y1, z), (x1, y0, z)])

    def walls(h, z0, z1):  # the four outer walls of the square |x|, |y| <= h
        return [quad_y(-h, -h, h, z0, z1, -1), quad_x(h, -h, h, z0, z1, 1),
                quad_y(h, -h, h, z0, z1, 1), quad_x(-h, -h, h, z0, z1, -1)]

    b, s, p = 5.0, 4.0, 1.5  # half widths: base, shaft, opening
    base_z, shaft_z, open_z, band_z, apex = 11.0, 61.0, 68.0, 71.0, 82.0
    blocks = {}
    blocks["base"] = walls(b, 0, base_z) + [  # the ledge around the shaft
        level(-b, b, -b, -s, base_z, True), level(-b, b, s, b, base_z, True),
        level(-b, -s, -s, s, base_z, True), level(s, b, -s, s, base_z, True)]
    blocks["shaft"] = walls(s, base_z, shaft_z)
    belfry = []
    for sign in (-1, 1):  # outer faces of the corner pillars, then the band above the openings
        for lo, hi in ((-s, -p), (p, s)):
            belfry.append(quad_y(sign * s, lo, hi, shaft_z, open_z, sign))
            belfry.append(quad_x(sign * s, lo, hi, shaft_z, open_z, sign))
    belfry += walls(s, open_z, band_z)
    for sx in (-1, 1):  # the pillars' faces towards the openings
        for sy in (-1, 1):
            ylo, yhi = sorted((sy * p, sy * s))
            xlo, xhi = sorted((sx * p, sx * s))
            belfry.append(quad_x(sx * p, ylo, yhi, shaft_z, open_z, -sx))
            belfry.append(quad_y(sy * p, xlo, xhi, shaft_z, open_z, -sy))
    # Floor (up) and ceiling (down) of the open storey: a cross of three rectangles each.
    for z, up in ((shaft_z, True), (open_z, False)):
        belfry += [level(-p, p, -s, s, z, up), level(-s, -p, -p, p, z, up),
                   level(p, s, -p, p, z, up)]
    blocks["belfry"] = belfry
    top = (0.0, 0.0, apex)
    blocks["roof"] = [[(-s, -s, band_z), (s, -s, band_z), top], [(s, -s, band_z), (s, s, band_z), top],
                      [(s, s, band_z), (-s, s, band_z), top], [(-s, s, band_z), (-s, -s, band_z), top]]
    return blocks


def surrounding_boxes(surroundings=SURROUNDINGS):
    """{name: box} of the surroundings that stand up from the ground (not the ground plane, not
    the trees)."""
    return {n: geo["box"] for n, (_, geo) in surroundings.items()
            if "box" in geo and geo["box"][4] != geo["box"][5]}


def write_surroundings_obj(path, surroundings=SURROUNDINGS):
    """The surrounding buildings (not the ground, not the trees), one OBJ group per box: walls
    and a flat roof, no bottom, counter-clockwise from outside (base.write_obj's format), as a
    user gives them to `rouen import --surroundings` from a city model's extruded footprints."""
    base.write_obj(path, {n: base.box_polygons(*b)
                          for n, b in surrounding_boxes(surroundings).items()})
    with open(path) as f:
        lines = f.read().split("\n")
    lines[0] = ("# rouen validation world (Blender/Cycles): the surroundings only (boxes as a "
                "city model's extruded footprints; not the ground, not the trees), by gen.py")
    with open(path, "w") as f:
        f.write("\n".join(lines))


TRUNK_R = 0.4  # every tree's trunk radius (m) in build_scene


def write_trees_csv(path, surroundings=SURROUNDINGS):
    """The trees as a survey or OpenStreetMap's natural=tree (height, diameter_crown) records
    them, for `rouen import --trees`: position, the crown's top, its diameter, the trunk's."""
    rows = ["# rouen validation world (Blender/Cycles): the trees (round crowns on trunks), by gen.py",
            "name,x_m,y_m,height_m,crown_diameter_m,trunk_diameter_m"]
    for name, (_, geo) in surroundings.items():
        if "tree" in geo:
            x, y, r, z = geo["tree"]
            rows.append(f"{name},{x:g},{y:g},{z + r:g},{2 * r:g},{2 * TRUNK_R:g}")
    with open(path, "w") as f:
        f.write("\n".join(rows) + "\n")


def check_outward(blocks):
    """Every face is counter-clockwise from outside: a point just in front of it lies outside
    the building, i.e. a ray from it going up (the building is open only at the ground)
    crosses the building's faces an even number of times."""
    tris = base.triangles(blocks)
    ray = np.array([0.31, 0.17, 0.94])
    ray /= np.linalg.norm(ray)
    for name, polys in blocks.items():
        for poly in polys:
            o = np.mean(np.array(poly, float), axis=0) + 1e-2 * base.polygon_normal(poly)
            crossings = 0
            for t in tris:
                e1, e2 = t[1] - t[0], t[2] - t[0]
                q = np.cross(ray, e2)
                det = q @ e1
                if abs(det) < 1e-12:
                    continue
                sv = o - t[0]
                u = (q @ sv) / det
                r = np.cross(sv, e1)
                v = (ray @ r) / det
                crossings += u >= 0 and v >= 0 and u + v <= 1 and (r @ e2) / det > 0
            if crossings % 2:
                raise RuntimeError(f"block {name}: polygon {poly} faces into the building")


def build_scene(blocks, block_materials=BLOCK_MATERIALS,
                surrounding_materials=SURROUNDING_MATERIALS, surroundings=SURROUNDINGS):
    """The Blender scene: the blocks, the surroundings (boxes and trees, "box"/"tree" entries as
    SURROUNDINGS), Nishita's sky at base.SITE's height, the render settings."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mats = {n: base.material(n, s) for n, s in {**block_materials, **surrounding_materials}.items()}
    building = [base.mesh_object("building_" + n, p, mats[n]) for n, p in blocks.items()]
    others = []
    for name, (mat, geo) in surroundings.items():
        if "box" in geo:
            x0, x1, y0, y1, z0, z1 = geo["box"]
            polys = ([[(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)]] if z0 == z1 else
                     base.box_polygons(x0, x1, y0, y1, z0, z1))
            others.append(base.mesh_object(name, polys, mats[mat]))
        else:
            x, y, r, z = geo["tree"]
            others.extend(base.tree_object(name, x, y, mats["crown"], mats["trunk"], trunk_r=TRUNK_R,
                                           trunk_h=z - 0.5 * r, crown_r=r, crown_z=z))
    sky = base.nishita_world(base.SITE["height_m"])
    base.setup_render()
    return building, others, sky


LIGHT_PASSES = {"diffuse": (("diffdir", "DiffDir"), ("diffind", "DiffInd")),
                "glossy": (("glossdir", "GlossDir"), ("glossind", "GlossInd"))}


def light_pass_output(tmpdir, kind="diffuse"):
    """Compositor: the render as it is, and a File Output node writing the Direct and Indirect
    passes of `kind` (diffuse or glossy; half float, PXR24) into tmpdir as <slot><frame>.exr,
    slots as LIGHT_PASSES; the caller mutes it for the frames that need none."""
    sc = bpy.context.scene
    vl = sc.view_layers[0]
    setattr(vl, f"use_pass_{kind}_direct", True)
    setattr(vl, f"use_pass_{kind}_indirect", True)
    sc.use_nodes = True
    nt = sc.node_tree
    rl = nt.nodes["Render Layers"]
    fo = nt.nodes.new("CompositorNodeOutputFile")
    fo.base_path = tmpdir
    fo.format.file_format = "OPEN_EXR"
    fo.format.color_mode = "RGB"
    fo.format.color_depth = "16"
    fo.format.exr_codec = "PXR24"
    fo.file_slots.clear()
    for slot, out in LIGHT_PASSES[kind]:
        fo.file_slots.new(slot)
        nt.links.new(rl.outputs[out], fo.inputs[slot])
    return fo


def sun_frame_check(out, frame, sun_k, pose, sun_dir, sun, slot):
    """rouen's sun against the disc Cycles rendered in the sun frame `frame` (checks.json)."""
    img = base.read_exr(os.path.join(out, frame))
    pred = base.project(sun_k, np.array(pose["rotation"]).T @ sun_dir)
    cu, cv, off, peak = base.sun_centroid(img, sun_k, pose["rotation"], sun_dir,
                                          sun["angular_radius_deg"])
    check = {"slot": slot, "rouen_pixel": [float(pred[0]), float(pred[1])],
             "disc_centroid_pixel": [cu, cv], "offset_deg": off, "peak_radiance": peak}
    print("sun check:", check, flush=True)
    return check


def mask_checks(cams, cameras, tris, building, others, tmpdir):
    """Every camera's building mask in Blender against rouen's camera model (checks.json)."""
    strength = bpy.context.scene.world.node_tree.nodes["Background"].inputs["Strength"]
    masks = {}
    for name, (ob, kind, k, _) in cams.items():
        pose = cameras[f"group={name}"]["pose"]
        masks[name] = base.mask_check(ob, kind, k, pose, tris, building, others,
                                      strength.default_value, tmpdir, name)
        print("mask check", name, masks[name], flush=True)
    return masks


def finish(out, truth, checks, tmpdir, t_start):
    """truth.json, checks.json (none when `checks` is None), the temporary folder removed."""
    with open(os.path.join(out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)
    if checks is not None:
        with open(os.path.join(out, "checks.json"), "w") as f:
            json.dump(checks, f, indent=1)
    shutil.rmtree(tmpdir)
    print(f"done in {time.time() - t_start:.0f} s; render seconds "
          f"{truth['render']['seconds_rendering']:.0f}", flush=True)


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(description="Render rouen's ground-only tower world")
    ap.add_argument("--out", required=True)
    ap.add_argument("--rouen", default=os.environ.get("ROUEN", "rouen"))
    ap.add_argument("--scale", type=float, default=1.0, help="multiplies every sample count")
    ap.add_argument("--times", default="", help="comma-separated slot indices (default: all)")
    ap.add_argument("--no-checks", action="store_true")
    ap.add_argument("--surroundings-only", action="store_true",
                    help="write OUT/surroundings.obj and OUT/trees.csv and render nothing")
    a = ap.parse_args(argv)
    if a.surroundings_only:
        write_surroundings_obj(os.path.join(os.path.abspath(a.out), "surroundings.obj"))
        write_trees_csv(os.path.join(os.path.abspath(a.out), "trees.csv"))
        return
    base.SITE.update(SITE)  # `rouen sun` (base.rouen_sun) asks for this site
    out = os.path.abspath(a.out)
    tmpdir = os.path.join(out, ".tmp")
    os.makedirs(tmpdir, exist_ok=True)
    os.makedirs(os.path.join(out, "passes"), exist_ok=True)  # not photos: rouen import skips it
    t_start = time.time()

    blocks = building_blocks()
    check_outward(blocks)
    base.write_obj(os.path.join(out, "building.obj"), blocks)
    write_surroundings_obj(os.path.join(out, "surroundings.obj"))
    write_trees_csv(os.path.join(out, "trees.csv"))
    tris = base.triangles(blocks)
    building, others, sky = build_scene(blocks)
    passes = light_pass_output(tmpdir)
    samples = {n: max(1, int(round(s * a.scale))) for n, s in SAMPLES.items()}

    cams = {}
    arch_k = base.pinhole_intrinsics(*ARCH_SIZE, ARCH_HFOV_DEG)
    for name, az, dist, eye_h, aim in ARCH_VIEWS:
        eye = (aim[0] + dist * math.sin(math.radians(az)),
               aim[1] + dist * math.cos(math.radians(az)), eye_h)
        ob = base.blender_camera(name, "pinhole", *ARCH_SIZE, ARCH_HFOV_DEG)
        base.place_camera(ob, "pinhole", base.look_at(eye, aim), eye)
        cams[name] = (ob, "pinhole", arch_k, "arch")
    pano_k = base.equirect_intrinsics(*PANO_SIZE)
    ob = base.blender_camera("pano", "equirect", *PANO_SIZE)
    base.place_camera(ob, "equirect", base.look_at((0, 0, 0), (0, 1, 0)), PANO_EYE)
    cams["pano"] = (ob, "equirect", pano_k, "pano")
    sun_k = base.pinhole_intrinsics(*SUN_SIZE, SUN_HFOV_DEG)
    sun_ob = base.blender_camera("sun", "pinhole", *SUN_SIZE, SUN_HFOV_DEG)

    slots = [int(s) for s in a.times.split(",")] if a.times else range(len(TIMES))
    targets = {"arch_se": "architecture", "arch_sw": "architecture", "arch_n": "architecture",
               "pano": "landscape+sky", "sun": "sun"}
    list_lines = ["# image  seconds  UTC  group  target   (HDR EXR: seconds = 1)"]
    cameras = {f"group={n}": {"intrinsics": k, "pose": base.rouen_pose(ob, kind)}
               for n, (ob, kind, k, _) in cams.items()}
    log = {"blender": bpy.app.version_string, "samples": samples, "renders": []}
    truth_times, checks = [], {"sun_frames": [], "masks": {}}
    for s in slots:
        local, utc_hm = TIMES[s]
        utc = f"{DATE}T{utc_hm}:00Z"
        sun = base.rouen_sun(a.rouen, utc)
        sky.sun_elevation = math.radians(sun["elevation_deg"])
        sky.sun_rotation = math.radians(sun["azimuth_deg"])
        sun_dir = base.enu_from_az_el(sun["azimuth_deg"], sun["elevation_deg"])
        base.place_camera(sun_ob, "pinhole", base.look_at(PANO_EYE, np.array(PANO_EYE) + sun_dir),
                          PANO_EYE)
        frames = {}
        for name, (ob, kind, k, role) in list(cams.items()) + [
                ("sun", (sun_ob, "pinhole", sun_k, "sun"))]:
            fname = f"t{s}_{name}.exr"
            passes.mute = role != "arch"
            seed = 1000 * s + len(frames)
            n = samples[role]
            secs = base.render(ob, k, os.path.join(out, fname), n, seed,
                               depth="32" if role == "sun" else "16", codec="PXR24")
            if role == "arch":
                for p in ("diffdir", "diffind"):
                    shutil.move(os.path.join(tmpdir, f"{p}{bpy.context.scene.frame_current:04d}.exr"),
                                os.path.join(out, "passes", f"t{s}_{name}_{p}.exr"))
            log["renders"].append({"file": fname, "seconds": round(secs, 2), "samples": n})
            print(f"rendered {fname} in {secs:.1f} s", flush=True)
            frames[name] = fname
            list_lines.append(f"{fname} 1 {utc} group={name} target={targets[name]}")
        cameras[frames["sun"]] = {"intrinsics": sun_k, "pose": base.rouen_pose(sun_ob, "pinhole")}
        truth_times.append({"slot": s, "local": f"{DATE}T{local}:00{ZONE}", "utc": utc,
                            "heldout": s == HELDOUT, "rouen_sun": sun, "frames": frames})
        if not a.no_checks:
            checks["sun_frames"].append(sun_frame_check(
                out, frames["sun"], sun_k, cameras[frames["sun"]]["pose"], sun_dir, sun, s))

    passes.mute = True
    if not a.no_checks:
        checks["masks"] = mask_checks(cams, cameras, tris, building, others, tmpdir)

    base.write_import_files(out, list_lines, cameras, log, t_start)
    truth = {
        "what": "rouen Blender/Cycles validation world photographed from the ground (gen.py)",
        "frame": "east-north-up metres: x east, y north, z up (Blender's and rouen's world)",
        "site": SITE, "date": DATE, "zone": ZONE, "heldout_slot": HELDOUT,
        "sun_diameter_deg": base.SUN_DIAMETER_DEG,
        "sky": {"model": "Cycles Nishita, sun disc on, sun_intensity 1, air 1, dust 1, ozone 1",
                "altitude_m": SITE["height_m"], "background_strength": 1.0},
        "albedo_note": ("albedo = Principled BSDF base colour (linear RGB); matte blocks: "
                        "roughness 1, specular 0 (Burley's diffuse, rouen retro 1); the ground: "
                        "roughness 0.9. The *_diffdir/_diffind frames are Cycles' Diffuse "
                        "Direct/Indirect passes: the diffuse light without the albedo."),
        "blocks": {n: {**m, "in_building_obj": True, "glossy": m["specular"] > 0}
                   for n, m in BLOCK_MATERIALS.items()},
        "surroundings": {n: {"material": mat, **SURROUNDING_MATERIALS[mat], **geo}
                         for n, (mat, geo) in SURROUNDINGS.items()},
        "times": truth_times,
        "cameras": {"architecture": [{"group": n, "azimuth_deg": az, "distance_m": d,
                                      "eye_height_m": e, "aim": aim}
                                     for n, az, d, e, aim in ARCH_VIEWS],
                    "pano_eye": PANO_EYE, "sun_eye": PANO_EYE, "sun_hfov_deg": SUN_HFOV_DEG},
        "render": log,
    }
    finish(out, truth, None if a.no_checks else checks, tmpdir, t_start)


if __name__ == "__main__":
    main()
