# A town hall on a courtyard, built from code and rendered by Blender/Cycles: rouen's third
# ground-level validation world (README.md: when it was first looked at):
#
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH [--scale S]
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH --plan
#
# An L-shaped hall at Toulouse in mid-October: a brick range 50 x 12 m along the square (walls
# 15 m, 40-degree tiled gable roof) and a rendered wing 12 x 28 m running north from its east
# end, so that the two enclose, with a row of houses and a low range on the west, a courtyard
# whose walls face north and west; a stone campanile 7 x 7 m, 44 m high with a 10 m copper
# spire, at the range's west end. The square south of the hall has trees; a street east of the
# wing has houses across it. Everything matte (Burley's diffuse), the ground rough. Lit by
# Cycles' Nishita sky with its sun disc at four training times (a low morning sun among them)
# and a held-out low evening sun from the west-south-west, which the low range west of the
# courtyard partly hides from the wing's west wall.
#
# What a person on the ground can take, and nothing else: two HDR panoramas per time at eye
# height (one in the square, one in the courtyard; each the landscape and the sky photo at
# once), a telephoto frame of the sun from the square, four architecture views at eye height,
# each with Cycles' Diffuse Direct and Indirect light passes.
#
# The pipeline is ../blender_nave/gen.py's main(), imported as `nave`, run on this module's
# geometry, materials, site, times and cameras (its module globals are replaced before it
# runs); nave's main writes a truth.json whose "building" entry this file then replaces.
import importlib.util
import json
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
_spec = importlib.util.spec_from_file_location("nave_gen",
                                               os.path.join(HERE, "..", "blender_nave", "gen.py"))
nave = importlib.util.module_from_spec(_spec)  # ../blender_nave/gen.py (main() is guarded)
_spec.loader.exec_module(nave)
base, tower = nave.base, nave.tower

SITE = {"lat_deg": 43.60, "lon_deg": 1.44, "height_m": 146.0}  # Toulouse
DATE = "2026-10-14"
ZONE = "+02:00"  # CEST
TIMES = [  # (local, UTC): four training times and one held-out low evening sun (last)
    ("09:45", "07:45"),
    ("11:45", "09:45"),
    ("14:00", "12:00"),
    ("16:15", "14:15"),
    ("18:15", "16:15"),
]
HELDOUT = 4

MATTE = base.MATTE
BLOCK_MATERIALS = {
    "hall": {"base_color": [0.52, 0.34, 0.26], **MATTE},  # brick
    "wing": {"base_color": [0.76, 0.71, 0.62], **MATTE},  # render
    "tower": {"base_color": [0.60, 0.57, 0.50], **MATTE},  # stone
    "spire": {"base_color": [0.28, 0.46, 0.40], **MATTE},  # weathered copper
    "roof": {"base_color": [0.48, 0.24, 0.16], **MATTE},  # clay tiles
}
SURROUNDING_MATERIALS = {
    "ground": {"base_color": [0.34, 0.31, 0.26], **tower.ROUGH_GROUND},  # paving and gravel
    "render": {"base_color": [0.72, 0.66, 0.56], **MATTE},
    "render2": {"base_color": [0.66, 0.62, 0.58], **MATTE},
    "brick": {"base_color": [0.56, 0.38, 0.30], **MATTE},
    "concrete": {"base_color": [0.58, 0.58, 0.56], **MATTE},
    "stone": {"base_color": [0.57, 0.54, 0.49], **MATTE},
    "crown": {"base_color": [0.12, 0.20, 0.07], **MATTE},
    "trunk": {"base_color": [0.25, 0.17, 0.10], **MATTE},
}

# The building (east-north-up metres, origin at the range's centre on the ground).
WALL_H = 15.0
PITCH_DEG = 40.0
RANGE = {"x": (-25.0, 25.0), "y": (-6.0, 6.0)}  # along the square, ridge along x
WING = {"x": (13.0, 25.0), "y": (6.0, 34.0)}  # north from the range's east end, ridge along y
TOWER = {"x": (-32.0, -25.0), "y": (-3.5, 3.5), "h": 44.0, "spire_h": 10.0}
RIDGE = WALL_H + 6.0 * math.tan(math.radians(PITCH_DEG))

SURROUNDINGS = {
    "ground": ("ground", {"box": [-2000, 2000, -2000, 2000, 0, 0]}),
    # the courtyard's north side: a row of houses
    "house_n1": ("render", {"box": [-46, -26, 42, 54, 0, 12.0]}),
    "house_n2": ("brick", {"box": [-26, -6, 42, 54, 0, 13.5]}),
    "house_n3": ("render2", {"box": [-6, 14, 42, 54, 0, 11.0]}),
    "house_n4": ("stone", {"box": [14, 34, 42, 54, 0, 14.0]}),
    # its west side: a low range (it hides the held-out evening sun from the wing's west wall)
    "range_w": ("stone", {"box": [-50, -38, 6, 40, 0, 9.0]}),
    # across the street east of the wing
    "house_e1": ("render2", {"box": [36, 50, 12, 26, 0, 12.0]}),
    "house_e2": ("brick", {"box": [36, 50, 26, 42, 0, 13.0]}),
    # further out, low
    "shops_s": ("concrete", {"box": [-30, 20, -100, -88, 0, 8.0]}),
    "house_se": ("render", {"box": [60, 74, -52, -40, 0, 10.0]}),
    "block_w": ("concrete", {"box": [-120, -100, -30, 10, 0, 12.0]}),
    # trees: one in the courtyard, three in the square, two further out
    "tree_court": ("crown", {"tree": [-30, 18, 3.5, 7.0]}),
    "tree_sq_w": ("crown", {"tree": [-24, -24, 3.0, 6.5]}),
    "tree_sq_e": ("crown", {"tree": [24, -22, 3.0, 6.5]}),
    "tree_sq_s": ("crown", {"tree": [-8, -52, 3.5, 7.0]}),
    "tree_far_e": ("crown", {"tree": [85, 5, 4.0, 8.0]}),
    "tree_far_sw": ("crown", {"tree": [-70, -70, 4.0, 8.0]}),
}

ARCH_VIEWS = [
    ("south", (-40.0, -75.0, nave.EYE_H), (0.0, -6.0, 10.0), 60.0),  # the square front, 75 m
    ("court", (-28.0, 37.0, nave.EYE_H), (13.0, 6.0, 6.0), 65.0),  # the courtyard's corner
    ("southeast", (75.0, -35.0, nave.EYE_H), (19.0, 5.0, 10.0), 60.0),  # the east end, the wing
    ("tower", (-75.0, -30.0, nave.EYE_H), (-28.5, 0.0, 22.0), 60.0),  # the campanile
]
PANOS = {"pano_square": (0.0, -30.0, nave.EYE_H),  # in the square, 24 m south of the range
         "pano_court": (-8.0, 24.0, nave.EYE_H)}  # in the courtyard
SUN_EYE = PANOS["pano_square"]


# The roofs' slopes and the spire's (steep: 10 m over a 3.5 m half-width) for nave.check_faces.
SLOPED = {"roof": 0.5, "spire": 0.2}
WHAT = ("rouen Blender/Cycles validation world: an L-shaped town hall with a campanile on a "
        "courtyard, photographed from the ground (gen.py)")


def building_entry():
    """truth.json's "building": the blocks' dimensions and every face's normal."""
    return {"range": RANGE, "wing": WING, "tower": TOWER, "wall_h": WALL_H,
            "pitch_deg": PITCH_DEG, "ridge_m": RIDGE, "faces": face_normals()}


def face_normals():
    return [{"block": b, "face": lab, "normal": base.polygon_normal(p).tolist()}
            for b, lab, p in building_faces()]


def _oriented(poly, want):
    """poly, reversed if its normal (counter-clockwise) points away from `want`."""
    return poly if base.polygon_normal(poly) @ np.array(want, float) > 0 else poly[::-1]


def oriented_faces(raw, sloped):
    """[(block, face label, polygon)] from [(block, label, polygon, outward direction)]: each
    polygon counter-clockwise from outside, the outward direction of the `sloped` blocks'
    faces tilted upwards (a roof's slope faces the sky as well as its side)."""
    up = np.array([0.0, 0.0, 1.0])
    return [(block, label, _oriented(poly, np.array(want, float) + (up if block in sloped else 0)))
            for block, label, poly, want in raw]


def building_faces():
    """[(block, face label, polygon)], counter-clockwise from outside, no bottom faces; the
    faces two blocks share are left out (the range's north wall where the wing stands against
    it, its west end where the campanile does)."""
    rx0, rx1 = RANGE["x"]
    ry0, ry1 = RANGE["y"]
    wx0, wx1 = WING["x"]
    wy0, wy1 = WING["y"]
    tx0, tx1 = TOWER["x"]
    ty0, ty1 = TOWER["y"]
    th, sh = TOWER["h"], TOWER["spire_h"]
    h, r = WALL_H, RIDGE
    ry_mid, wx_mid = 0.5 * (ry0 + ry1), 0.5 * (wx0 + wx1)
    slope = math.tan(math.radians(PITCH_DEG))
    z_at_tower = h + (ry1 - ty1) * slope  # the range's roof where the campanile's sides meet it
    S, N, E, W = (0, -1, 0), (0, 1, 0), (1, 0, 0), (-1, 0, 0)
    raw = [
        # the range: south wall, north wall west of the wing, the east end and its gable, the
        # west end on either side of the campanile
        ("hall", "south", [(rx0, ry0, 0), (rx1, ry0, 0), (rx1, ry0, h), (rx0, ry0, h)], S),
        ("hall", "north", [(rx0, ry1, 0), (wx0, ry1, 0), (wx0, ry1, h), (rx0, ry1, h)], N),
        ("hall", "east", [(rx1, ry0, 0), (rx1, ry1, 0), (rx1, ry1, h), (rx1, ry0, h)], E),
        ("hall", "east", [(rx1, ry0, h), (rx1, ry1, h), (rx1, ry_mid, r)], E),
        ("hall", "west", [(rx0, ry0, 0), (rx0, ty0, 0), (rx0, ty0, z_at_tower), (rx0, ry0, h)], W),
        ("hall", "west", [(rx0, ty1, 0), (rx0, ry1, 0), (rx0, ry1, h), (rx0, ty1, z_at_tower)], W),
        # the wing: its long walls, the north end and its gable, the south gable above the
        # range's eave
        ("wing", "west", [(wx0, wy0, 0), (wx0, wy1, 0), (wx0, wy1, h), (wx0, wy0, h)], W),
        ("wing", "east", [(wx1, wy0, 0), (wx1, wy1, 0), (wx1, wy1, h), (wx1, wy0, h)], E),
        ("wing", "north", [(wx0, wy1, 0), (wx1, wy1, 0), (wx1, wy1, h), (wx0, wy1, h)], N),
        ("wing", "north", [(wx0, wy1, h), (wx1, wy1, h), (wx_mid, wy1, r)], N),
        ("wing", "south", [(wx0, wy0, h), (wx1, wy0, h), (wx_mid, wy0, r)], S),
        # the campanile: three sides to the top, the east side above the range's roof
        ("tower", "west", [(tx0, ty0, 0), (tx0, ty1, 0), (tx0, ty1, th), (tx0, ty0, th)], W),
        ("tower", "south", [(tx0, ty0, 0), (tx1, ty0, 0), (tx1, ty0, th), (tx0, ty0, th)], S),
        ("tower", "north", [(tx0, ty1, 0), (tx1, ty1, 0), (tx1, ty1, th), (tx0, ty1, th)], N),
        ("tower", "east", [(tx1, ty0, z_at_tower), (tx1, ry_mid, r), (tx1, ry_mid, th),
                           (tx1, ty0, th)], E),  # two convex halves (fans triangulate them)
        ("tower", "east", [(tx1, ry_mid, r), (tx1, ty1, z_at_tower), (tx1, ty1, th),
                           (tx1, ry_mid, th)], E),
        # the roofs: the range's two slopes, the wing's two
        ("roof", "south", [(rx0, ry0, h), (rx1, ry0, h), (rx1, ry_mid, r), (rx0, ry_mid, r)], S),
        ("roof", "north", [(rx0, ry1, h), (rx1, ry1, h), (rx1, ry_mid, r), (rx0, ry_mid, r)], N),
        ("roof", "west", [(wx0, wy0, h), (wx0, wy1, h), (wx_mid, wy1, r), (wx_mid, wy0, r)], W),
        ("roof", "east", [(wx1, wy0, h), (wx1, wy1, h), (wx_mid, wy1, r), (wx_mid, wy0, r)], E),
    ]
    apex = (0.5 * (tx0 + tx1), 0.5 * (ty0 + ty1), th + sh)
    corners = [(tx0, ty0), (tx1, ty0), (tx1, ty1), (tx0, ty1)]
    for (ax, ay), (bx, by), label, want in zip(corners, corners[1:] + corners[:1],
                                               ("south", "east", "north", "west"), (S, E, N, W)):
        raw.append(("spire", label, [(ax, ay, th), (bx, by, th), apex], want))
    return oriented_faces(raw, SLOPED)


# The definitions a world gives the nave's pipeline.
WORLD_NAMES = ("SITE", "DATE", "ZONE", "TIMES", "HELDOUT", "BLOCK_MATERIALS",
               "SURROUNDING_MATERIALS", "SURROUNDINGS", "ARCH_VIEWS", "PANOS", "SUN_EYE", "RIDGE",
               "building_faces")


def install_world(world):
    """Another world's definitions (its module's globals: WORLD_NAMES, and WHAT,
    building_entry and SLOPED for truth.json) in place of this one's, then install()."""
    for name in WORLD_NAMES + ("WHAT", "building_entry", "SLOPED"):
        globals()[name] = world[name]
    install()


def install():
    """This world's definitions in place of the nave's, for nave.main() to render."""
    for name in WORLD_NAMES:
        setattr(nave, name, globals()[name])
    nave.SLOPED = SLOPED
    nave.GLINT_SLOT = None  # no view named `glint`: no glossy passes


def rewrite_truth(out):
    """nave.main()'s truth.json describes its own building; this world's (WHAT,
    building_entry()) replaces it, with the matte worlds' albedo note."""
    path = os.path.join(out, "truth.json")
    if not os.path.exists(path):
        return
    with open(path) as f:
        truth = json.load(f)
    truth["what"] = WHAT
    truth["albedo_note"] = ("albedo = Principled BSDF base colour (linear RGB); every block "
                            "matte: roughness 1, specular 0 (Burley's diffuse, rouen retro 1); "
                            "the ground: roughness 0.9. passes/*_diffdir/_diffind are Cycles' "
                            "Diffuse Direct/Indirect passes (the diffuse light without the "
                            "albedo).")
    truth.pop("roof_shader", None)
    truth.pop("glint_slot", None)
    truth.pop("street", None)
    truth["building"] = building_entry()
    with open(path, "w") as f:
        json.dump(truth, f, indent=1)


def run():
    """Renders the installed world (nave.main() reads the command line), then its truth.json."""
    nave.main()
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    if "--out" in argv and "--plan" not in argv:
        rewrite_truth(os.path.abspath(argv[argv.index("--out") + 1]))


if __name__ == "__main__":
    install()
    run()
