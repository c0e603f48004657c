# A cathedral's west front on its square, built from code and rendered by Blender/Cycles:
# rouen's fifth ground-level validation world (README.md: when it was first looked at):
#
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH [--scale S]
#   blender -b --factory-startup --python gen.py -- --out DIR --rouen PATH --plan
#
# Rouen Cathedral's setting in matte blocks, at Rouen at the June solstice: a limestone west
# front 60 m wide facing the square (parvis) to the west: a facade screen 37 m wide and 30 m
# high between two towers flush with it, the north one 12 x 12 m and 75 m high, the south one
# 11 x 11 m and 60 m high; behind it a nave 90 x 30 m running east (walls 28 m, a 50-degree
# lead-grey gable roof to 45.9 m, whose west gable rises above the facade's top). The square
# is 62 m deep with 12-18 m houses round it and a street leaving its west side towards the
# evening sun; north of the nave a 9 m street (rue Saint-Romain) between it and a row of
# 14-20 m houses, opening at its west end into a small court beside the north tower; south of
# the nave an open place. Trees at three of the square's corners and further out; low
# buildings 100-150 m out. Everything matte (Burley's diffuse), the ground rough. Lit by
# Cycles' Nishita sky with its sun disc at four training times (08:30-17:30 CEST, the sun up
# to 63 degrees) and a held-out low evening sun (20:45 CEST, 10 degrees high from the WNW).
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

SITE = {"lat_deg": 49.4402, "lon_deg": 1.0952, "height_m": 20.0}  # Rouen, the cathedral
DATE = "2027-06-21"
ZONE = "+02:00"  # CEST
TIMES = [  # (local, UTC): four training times and one held-out low evening sun (last)
    ("08:30", "06:30"),
    ("11:30", "09:30"),
    ("14:30", "12:30"),
    ("17:30", "15:30"),
    ("20:45", "18:45"),
]
HELDOUT = 4

MATTE = base.MATTE
BLOCK_MATERIALS = {
    "facade": {"base_color": [0.68, 0.64, 0.55], **MATTE},  # limestone
    "tower_n": {"base_color": [0.57, 0.56, 0.52], **MATTE},  # older, greyer limestone
    "tower_s": {"base_color": [0.74, 0.68, 0.54], **MATTE},  # the yellower "butter" tower
    "nave": {"base_color": [0.62, 0.57, 0.48], **MATTE},  # limestone
    "roof": {"base_color": [0.24, 0.25, 0.27], **MATTE},  # lead
}
SURROUNDING_MATERIALS = {
    "ground": {"base_color": [0.33, 0.31, 0.28], **tower.ROUGH_GROUND},  # paving
    "render": {"base_color": [0.75, 0.71, 0.63], **MATTE},
    "render2": {"base_color": [0.66, 0.63, 0.59], **MATTE},
    "timber": {"base_color": [0.46, 0.36, 0.27], **MATTE},  # half-timbered fronts
    "stone": {"base_color": [0.60, 0.58, 0.53], **MATTE},
    "concrete": {"base_color": [0.59, 0.59, 0.57], **MATTE},
    "crown": {"base_color": [0.10, 0.21, 0.07], **MATTE},
    "trunk": {"base_color": [0.25, 0.17, 0.10], **MATTE},
}

# The building (east-north-up metres, origin at the west front's foot on the nave's axis).
WALL_H = 28.0
PITCH_DEG = 50.0
FACADE = {"x": (0.0, 8.0), "y": (-19.0, 18.0), "h": 30.0}  # the screen between the towers
TOWER_N = {"x": (0.0, 12.0), "y": (18.0, 30.0), "h": 75.0}  # Saint-Romain
TOWER_S = {"x": (0.0, 11.0), "y": (-30.0, -19.0), "h": 60.0}  # the Butter Tower
NAVE = {"x": (8.0, 98.0), "y": (-15.0, 15.0)}
RIDGE = WALL_H + 15.0 * math.tan(math.radians(PITCH_DEG))

SURROUNDINGS = {
    "ground": ("ground", {"box": [-2000, 2000, -2000, 2000, 0, 0]}),
    # the square's west side, cut by the street leaving it west-north-west (y -30..-14)
    "house_w1": ("timber", {"box": [-76, -62, -66, -30, 0, 13.0]}),
    "house_w2": ("render", {"box": [-76, -62, -14, 12, 0, 14.0]}),
    "house_w3": ("stone", {"box": [-76, -62, 12, 54, 0, 17.0]}),
    # its north side, and the south side
    "house_nw": ("render2", {"box": [-62, -30, 42, 54, 0, 18.0]}),
    "house_n0": ("timber", {"box": [-30, 8, 42, 54, 0, 15.0]}),
    "house_s1": ("render", {"box": [-62, -30, -66, -52, 0, 15.0]}),
    "house_s2": ("stone", {"box": [-30, 0, -66, -52, 0, 12.0]}),
    # the court north of the nave's west bay, and the row across rue Saint-Romain
    "house_court": ("render2", {"box": [14, 40, 38, 50, 0, 14.0]}),
    "house_n1": ("timber", {"box": [40, 62, 24, 36, 0, 16.0]}),
    "house_n2": ("render", {"box": [62, 84, 24, 36, 0, 14.0]}),
    "house_n3": ("stone", {"box": [84, 106, 24, 36, 0, 20.0]}),
    # the open place south of the nave; its east side
    "house_se": ("render2", {"box": [86, 104, -62, -40, 0, 13.0]}),
    # further out, low
    "block_e": ("concrete", {"box": [118, 142, -25, 30, 0, 14.0]}),
    "block_n": ("concrete", {"box": [-20, 40, 72, 86, 0, 12.0]}),
    "block_s": ("stone", {"box": [-40, -5, -130, -112, 0, 10.0]}),
    "block_w": ("render", {"box": [-150, -125, -90, -55, 0, 12.0]}),
    # trees at three of the square's corners, and further out
    "tree_sq_sw": ("crown", {"tree": [-55, -45, 3.5, 7.0]}),
    "tree_sq_nw": ("crown", {"tree": [-55, 35, 3.5, 7.0]}),
    "tree_sq_se": ("crown", {"tree": [-10, -46, 3.0, 6.5]}),
    "tree_far_w": ("crown", {"tree": [-105, 30, 4.0, 8.0]}),
    "tree_far_e": ("crown", {"tree": [112, -30, 4.0, 8.0]}),
    "tree_far_s": ("crown", {"tree": [15, -125, 4.5, 8.5]}),
}

ARCH_VIEWS = [
    ("front", (-57.0, -4.0, nave.EYE_H), (4.0, 0.0, 22.0), 60.0),  # the west front, 57 m
    ("northwest", (-46.0, 38.0, nave.EYE_H), (6.0, 12.0, 26.0), 60.0),  # front, north tower
    ("street", (24.0, 21.5, nave.EYE_H), (75.0, 15.0, 10.0), 70.0),  # the nave's north wall
    ("southeast", (62.0, -88.0, nave.EYE_H), (28.0, -15.0, 24.0), 60.0),  # south side, towers
]
PANOS = {"pano_square": (-25.0, -40.0, nave.EYE_H),  # in the square's south half
         "pano_street": (52.0, 19.5, nave.EYE_H)}  # in rue Saint-Romain, mid-way to the houses
SUN_EYE = PANOS["pano_square"]


def building_faces():
    """[(block, face label, polygon)], counter-clockwise from outside, no bottom faces; the
    faces two blocks share are left out (the facade's ends against the towers, the towers'
    inner sides below the facade's top, the facade's east side where the nave stands)."""
    fx0, fx1 = FACADE["x"]
    fy0, fy1 = FACADE["y"]
    fh = FACADE["h"]
    nx0, nx1 = TOWER_N["x"]
    ny0, ny1 = TOWER_N["y"]
    nh = TOWER_N["h"]
    sx0, sx1 = TOWER_S["x"]
    sy0, sy1 = TOWER_S["y"]
    sh = TOWER_S["h"]
    x0, x1 = NAVE["x"]
    y0, y1 = NAVE["y"]
    h, r = WALL_H, RIDGE
    mid = 0.5 * (y0 + y1)
    yf = (y1 - mid) - (fh - h) / math.tan(math.radians(PITCH_DEG))  # the roof at the facade's top
    S, N, E, W, U = (0, -1, 0), (0, 1, 0), (1, 0, 0), (-1, 0, 0), (0, 0, 1)
    raw = [
        # the facade: its west front, its top, its east side beside and above the nave's section
        ("facade", "west", [(fx0, fy0, 0), (fx0, fy1, 0), (fx0, fy1, fh), (fx0, fy0, fh)], W),
        ("facade", "top", [(fx0, fy0, fh), (fx1, fy0, fh), (fx1, fy1, fh), (fx0, fy1, fh)], U),
        ("facade", "east", [(fx1, fy0, 0), (fx1, y0, 0), (fx1, y0, fh), (fx1, fy0, fh)], E),
        ("facade", "east", [(fx1, y1, 0), (fx1, fy1, 0), (fx1, fy1, fh), (fx1, y1, fh)], E),
        ("facade", "east", [(fx1, y0, h), (fx1, mid - yf, fh), (fx1, y0, fh)], E),
        ("facade", "east", [(fx1, y1, h), (fx1, y1, fh), (fx1, mid + yf, fh)], E),
        # the north tower: three sides to the top, its south side beside and above the facade
        ("tower_n", "west", [(nx0, ny0, 0), (nx0, ny1, 0), (nx0, ny1, nh), (nx0, ny0, nh)], W),
        ("tower_n", "north", [(nx0, ny1, 0), (nx1, ny1, 0), (nx1, ny1, nh), (nx0, ny1, nh)], N),
        ("tower_n", "east", [(nx1, ny0, 0), (nx1, ny1, 0), (nx1, ny1, nh), (nx1, ny0, nh)], E),
        ("tower_n", "south", [(fx1, ny0, 0), (nx1, ny0, 0), (nx1, ny0, fh), (fx1, ny0, fh)], S),
        ("tower_n", "south", [(nx0, ny0, fh), (nx1, ny0, fh), (nx1, ny0, nh), (nx0, ny0, nh)], S),
        ("tower_n", "top", [(nx0, ny0, nh), (nx1, ny0, nh), (nx1, ny1, nh), (nx0, ny1, nh)], U),
        # the south tower, likewise
        ("tower_s", "west", [(sx0, sy0, 0), (sx0, sy1, 0), (sx0, sy1, sh), (sx0, sy0, sh)], W),
        ("tower_s", "south", [(sx0, sy0, 0), (sx1, sy0, 0), (sx1, sy0, sh), (sx0, sy0, sh)], S),
        ("tower_s", "east", [(sx1, sy0, 0), (sx1, sy1, 0), (sx1, sy1, sh), (sx1, sy0, sh)], E),
        ("tower_s", "north", [(fx1, sy1, 0), (sx1, sy1, 0), (sx1, sy1, fh), (fx1, sy1, fh)], N),
        ("tower_s", "north", [(sx0, sy1, fh), (sx1, sy1, fh), (sx1, sy1, sh), (sx0, sy1, sh)], N),
        ("tower_s", "top", [(sx0, sy0, sh), (sx1, sy0, sh), (sx1, sy1, sh), (sx0, sy1, sh)], U),
        # the nave: its long walls, the east end and its gable, the west gable above the facade
        ("nave", "south", [(x0, y0, 0), (x1, y0, 0), (x1, y0, h), (x0, y0, h)], S),
        ("nave", "north", [(x0, y1, 0), (x1, y1, 0), (x1, y1, h), (x0, y1, h)], N),
        ("nave", "east", [(x1, y0, 0), (x1, y1, 0), (x1, y1, h), (x1, y0, h)], E),
        ("nave", "east", [(x1, y0, h), (x1, y1, h), (x1, mid, r)], E),
        ("nave", "west", [(x0, mid - yf, fh), (x0, mid + yf, fh), (x0, mid, r)], W),
        # the roof's two slopes
        ("roof", "south", [(x0, y0, h), (x1, y0, h), (x1, mid, r), (x0, mid, r)], S),
        ("roof", "north", [(x0, y1, h), (x1, y1, h), (x1, mid, r), (x0, mid, r)], N),
    ]
    return court.oriented_faces(raw, SLOPED)


SLOPED = {"roof": 0.5}  # sloped block: the least upward part of its normal (nave.check_faces)
WHAT = ("rouen Blender/Cycles validation world: a cathedral's west front with two towers and "
        "its nave on a square, photographed from the ground (gen.py)")


def building_entry():
    """truth.json's "building": the blocks' dimensions and every face's normal."""
    return {"facade": FACADE, "tower_n": TOWER_N, "tower_s": TOWER_S, "nave": NAVE,
            "wall_h": WALL_H, "pitch_deg": PITCH_DEG, "ridge_m": RIDGE,
            "faces": court.face_normals()}


def install():
    """This world's definitions in court's module, then in nave's."""
    court.install_world(globals())


if __name__ == "__main__":
    install()
    court.run()
