# A cloth hall with a belfry on a market square, built from code and rendered by Blender/Cycles:
# rouen's fourth ground-level validation world (README.md: when it was first looked at):
#
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH [--scale S]
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH --plan
#
# A limestone hall 44 x 14 m (walls 18 m, a 50-degree slate-grey gable roof to 26.3 m) at Ypres
# at the March equinox, a brick belfry 8 x 8 m and 56 m high standing against the middle of its
# south front on the square; a 9 m market street along its north side between the hall and a
# row of 12-16 m houses (the hall's north wall is never sunlit in March); trees at the square's
# edges, low buildings further out. Everything matte (Burley's diffuse), the ground rough. Lit
# by Cycles' Nishita sky with its sun disc at four training times and a held-out low evening
# sun from the west-south-west.
#
# What a person on the ground can take, and nothing else: two HDR panoramas per time at eye
# height (one in the square, one in the street), a telephoto frame of the sun from the square,
# four architecture views at eye height, each with Cycles' Diffuse Direct and Indirect passes.
#
# The pipeline is ../blender_nave/gen.py's main(), run through ../blender_court/gen.py (imported
# as `court`: its install() puts a world's definitions in place of the nave's, its run() renders
# and rewrites truth.json); this file gives the geometry, materials, site, times, cameras and
# truth.json's "what" and "building" entries.
import importlib.util
import math
import os


HERE = os.path.dirname(os.path.abspath(__file__))
_spec = importlib.util.spec_from_file_location("court_gen",
                                               os.path.join(HERE, "..", "blender_court", "gen.py"))
court = importlib.util.module_from_spec(_spec)  # ../blender_court/gen.py (its main is guarded)
_spec.loader.exec_module(court)
nave, base, tower = court.nave, court.base, court.tower

SITE = {"lat_deg": 50.85, "lon_deg": 2.89, "height_m": 20.0}  # Ypres
DATE = "2027-03-20"
ZONE = "+01:00"  # CET
TIMES = [  # (local, UTC): four training times and one held-out low evening sun (last)
    ("09:30", "08:30"),
    ("11:30", "10:30"),
    ("13:30", "12:30"),
    ("15:30", "14:30"),
    ("17:45", "16:45"),
]
HELDOUT = 4

MATTE = base.MATTE
BLOCK_MATERIALS = {
    "hall": {"base_color": [0.66, 0.62, 0.54], **MATTE},  # limestone
    "roof": {"base_color": [0.22, 0.22, 0.25], **MATTE},  # slate-grey tiles
    "belfry": {"base_color": [0.50, 0.30, 0.22], **MATTE},  # brick
}
SURROUNDING_MATERIALS = {
    "ground": {"base_color": [0.32, 0.30, 0.27], **tower.ROUGH_GROUND},  # cobbles
    "render": {"base_color": [0.74, 0.70, 0.62], **MATTE},
    "brick": {"base_color": [0.52, 0.32, 0.25], **MATTE},
    "stone": {"base_color": [0.58, 0.56, 0.52], **MATTE},
    "concrete": {"base_color": [0.60, 0.60, 0.58], **MATTE},
    "crown": {"base_color": [0.11, 0.21, 0.08], **MATTE},
    "trunk": {"base_color": [0.25, 0.17, 0.10], **MATTE},
}

# The building (east-north-up metres, origin at the hall's centre on the ground).
WALL_H = 18.0
PITCH_DEG = 50.0
HALL = {"x": (-22.0, 22.0), "y": (-7.0, 7.0)}
BELFRY = {"x": (-4.0, 4.0), "y": (-15.0, -7.0), "h": 56.0}
RIDGE = WALL_H + 7.0 * math.tan(math.radians(PITCH_DEG))

SURROUNDINGS = {
    "ground": ("ground", {"box": [-2000, 2000, -2000, 2000, 0, 0]}),
    # the row of houses across the market street, north of the hall
    "house_n1": ("brick", {"box": [-40, -22, 16, 28, 0, 14.0]}),
    "house_n2": ("render", {"box": [-22, -4, 16, 28, 0, 12.5]}),
    "house_n3": ("stone", {"box": [-4, 14, 16, 28, 0, 16.0]}),
    "house_n4": ("brick", {"box": [14, 32, 16, 28, 0, 13.0]}),
    # the square's far side and its ends
    "row_s": ("render", {"box": [-30, 30, -78, -66, 0, 11.0]}),
    "house_w": ("stone", {"box": [-62, -48, -40, -10, 0, 12.0]}),
    "house_e": ("concrete", {"box": [50, 64, -75, -55, 0, 10.0]}),
    "block_ne": ("brick", {"box": [50, 80, 15, 40, 0, 14.0]}),
    # trees at the square's corners and further out
    "tree_sq_sw": ("crown", {"tree": [-38, -58, 3.5, 7.0]}),
    "tree_sq_se": ("crown", {"tree": [36, -58, 3.5, 7.0]}),
    "tree_sq_e": ("crown", {"tree": [44, -62, 3.0, 6.5]}),
    "tree_far_w": ("crown", {"tree": [-90, 10, 4.0, 8.0]}),
    "tree_far_n": ("crown", {"tree": [10, 60, 4.0, 8.0]}),
}

ARCH_VIEWS = [
    ("front", (-12.0, -62.0, nave.EYE_H), (0.0, -7.0, 20.0), 60.0),  # the square front, 55 m
    ("street", (-24.0, 11.5, nave.EYE_H), (8.0, 7.0, 8.0), 70.0),  # in the street, the north wall
    ("east", (60.0, -40.0, nave.EYE_H), (14.0, -4.0, 14.0), 60.0),  # the east end, from the SE
    ("belfry", (-52.0, -52.0, nave.EYE_H), (-2.0, -11.0, 26.0), 60.0),  # the belfry from the SW
]
PANOS = {"pano_square": (8.0, -40.0, nave.EYE_H),  # in the square, 25 m south of the belfry
         "pano_street": (0.0, 11.5, nave.EYE_H)}  # in the street, mid-way to the houses
SUN_EYE = PANOS["pano_square"]


def building_faces():
    """[(block, face label, polygon)], counter-clockwise from outside, no bottom faces; the
    hall's south wall is left out where the belfry stands against it."""
    hx0, hx1 = HALL["x"]
    hy0, hy1 = HALL["y"]
    bx0, bx1 = BELFRY["x"]
    by0, by1 = BELFRY["y"]
    bh, h, r = BELFRY["h"], WALL_H, RIDGE
    mid = 0.5 * (hy0 + hy1)
    S, N, E, W, U = (0, -1, 0), (0, 1, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1)
    raw = [
        ("hall", "south", [(hx0, hy0, 0), (bx0, hy0, 0), (bx0, hy0, h), (hx0, hy0, h)], S),
        ("hall", "south", [(bx1, hy0, 0), (hx1, hy0, 0), (hx1, hy0, h), (bx1, hy0, h)], S),
        ("hall", "north", [(hx0, hy1, 0), (hx1, hy1, 0), (hx1, hy1, h), (hx0, hy1, h)], N),
        ("hall", "east", [(hx1, hy0, 0), (hx1, hy1, 0), (hx1, hy1, h), (hx1, hy0, h)], E),
        ("hall", "east", [(hx1, hy0, h), (hx1, hy1, h), (hx1, mid, r)], E),
        ("hall", "west", [(hx0, hy0, 0), (hx0, hy1, 0), (hx0, hy1, h), (hx0, hy0, h)], W),
        ("hall", "west", [(hx0, hy0, h), (hx0, hy1, h), (hx0, mid, r)], W),
        ("roof", "south", [(hx0, hy0, h), (hx1, hy0, h), (hx1, mid, r), (hx0, mid, r)], S),
        ("roof", "north", [(hx0, hy1, h), (hx1, hy1, h), (hx1, mid, r), (hx0, mid, r)], N),
        ("belfry", "south", [(bx0, by0, 0), (bx1, by0, 0), (bx1, by0, bh), (bx0, by0, bh)], S),
        ("belfry", "east", [(bx1, by0, 0), (bx1, by1, 0), (bx1, by1, bh), (bx1, by0, bh)], E),
        ("belfry", "west", [(bx0, by0, 0), (bx0, by1, 0), (bx0, by1, bh), (bx0, by0, bh)], W),
        ("belfry", "north", [(bx0, by1, h), (bx1, by1, h), (bx1, by1, bh), (bx0, by1, bh)], N),
        ("belfry", "top", [(bx0, by0, bh), (bx1, by0, bh), (bx1, by1, bh), (bx0, by1, bh)], U),
    ]
    return court.oriented_faces(raw, SLOPED)


SLOPED = {"roof": 0.5}  # sloped block: the least upward part of its normal (nave.check_faces)
WHAT = ("rouen Blender/Cycles validation world: a cloth hall with a belfry on a market square, "
        "photographed from the ground (gen.py)")


def building_entry():
    """truth.json's "building": the blocks' dimensions and every face's normal."""
    return {"hall": HALL, "belfry": BELFRY, "wall_h": WALL_H, "pitch_deg": PITCH_DEG,
            "ridge_m": RIDGE, "faces": court.face_normals()}


def install():
    """This world's definitions in court's module, then in nave's."""
    court.install_world(globals())


if __name__ == "__main__":
    install()
    court.run()
