"""Writes the solve rule's output: what the scene was solved from (the inputs hash rouen solve
recorded, rouen's version, the held-out slots), a function of the scene alone, so that Snakemake
reruns validate and report only when the scene changed (it compares the checksum of a newer small
input with the one it recorded). Fails when the scene is not there.

    python3 solved_stamp.py SCENE SESSION OUT.json
"""

import json
import sys


def main(scene, session, out):
    with open(f"{scene}/scene.json") as f:
        solved = json.load(f)
    stamp = {
        "session": session,
        "inputs_sha256": solved["provenance"]["inputs_sha256"],
        "rouen_version": solved["provenance"]["rouen_version"],
        "holdout_slots": solved.get("holdout_slots", []),
    }
    with open(out, "w") as f:
        f.write(json.dumps(stamp, indent=2) + "\n")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
